"""Leaderboard 1.0's scoring (icrsumo.scoring.lb1) on hand-built logs and records, no SUMO.

Logs as tests/hand_logs.py builds them: 20 Hz steps, the ego centre at x = 0.25 + 0.5 i on
step i (t = 0.05 i), a straight 100 m route along +x unless stated. Expected values are worked
out in the comments from the leaderboard's rules (statistics_manager.py, CollisionTest,
OutsideRouteLanesTest).
"""

from __future__ import annotations

import json
import math
import random
from dataclasses import replace

import pytest
from hand_logs import ROUTE, contact, make_log, straight  # tests/ is on pytest's pythonpath
from records_example import rec, tiny

from icrsumo.core.fsio import dumps_json
from icrsumo.core.types import EpisodeLog, EpisodeRecord, Event
from icrsumo.scoring import score_episode
from icrsumo.scoring.lb1 import LB1, counted_collisions, leaderboard_checkpoint
from icrsumo.scoring.penalties import PENALTIES


def test_penalty_constants():
    assert {str(k): v for k, v in PENALTIES.items()} == {
        "collision_pedestrian": 0.5, "collision_vehicle": 0.6, "collision_static": 0.65, "red_light": 0.7,
        "stop_sign": 0.8}


def test_clean_completion():
    res = score_episode(make_log(straight(201), ROUTE, termination="completed"))
    assert (res.rc, res.is_, res.ds, res.infractions, res.outside_lanes_pct) == (100.0, 1.0, 100.0, (), 0.0)


def test_repeated_contacts_with_one_actor():
    # veh1 touches on steps 20-29 (t 1.0-1.45): counted once at t = 1.0 (the same actor is then
    # ignored); at step 100 (t = 5.0) it is still the last actor (5.0 - 1.0 <= 5 s): ignored; it
    # is forgotten at t = 6.05 (> 5 s), so the contact at step 140 (t = 7.0, 60 m from the first
    # place, which was forgotten beyond 5 m) counts again: 2 x 0.6 -> IS 0.36
    evs = tuple(contact("collision_vehicle", i, "veh1") for i in [*range(20, 30), 100, 140, 141])
    log = make_log(straight(201), ROUTE, events=evs, termination="completed")
    assert [e.t for e in counted_collisions(log)] == [1.0, 7.0]
    res = score_episode(log)
    assert res.is_ == pytest.approx(0.36) and res.ds == pytest.approx(36.0)


def test_two_actors_at_one_place_and_static_contacts():
    # veh1 at step 20 (x = 10.25) counts there; veh2 at step 24 (x = 12.25, 2 m away) is within
    # 3 m of that place: ignored; veh3 at step 28 (x = 14.25, 4 m) counts; the roadside at
    # step 30 (x = 15.25, 1 m from the last place) is ignored; the roadside at step 60
    # (x = 30.25) counts, again at step 64 (2 m) is ignored, at step 70 (x = 35.25, 5 m) counts
    # (the static layout has no identity, only places): 0.6^2 x 0.65^2 = 0.1521
    evs = (contact("collision_vehicle", 20, "veh1"), contact("collision_vehicle", 24, "veh2"),
           contact("collision_vehicle", 28, "veh3"), contact("collision_static", 30, "roadside"),
           contact("collision_static", 60, "roadside"), contact("collision_static", 64, "roadside"),
           contact("collision_static", 70, "roadside"))
    log = make_log(straight(201), ROUTE, events=evs, termination="completed")
    assert [(e.other, e.t) for e in counted_collisions(log)] == [
        ("veh1", 1.0), ("veh3", 1.4), ("roadside", 3.0), ("roadside", 3.5)]
    assert score_episode(log).is_ == pytest.approx(0.1521)


def test_pedestrian_red_light_and_stop_sign_factors():
    evs = (contact("collision_pedestrian", 10, "p0"), Event("red_light", 2.0, 0.0, "tl1"),
           Event("stop_sign", 3.0, 0.0, "j2"), Event("wrong_way", 3.5, 0.0, "e_0"))
    res = score_episode(make_log(straight(201), ROUTE, events=evs, termination="completed"))
    assert [str(i.kind) for i in res.infractions] == ["collision_pedestrian", "red_light", "stop_sign"]
    assert res.is_ == pytest.approx(0.5 * 0.7 * 0.8)


def test_a_wrong_turn_into_a_legal_lane_costs_rc_not_is():
    # as in tests/scoring/test_criteria.py: deviation at (50, 30) with RC 24.5 %; the lane taken is legal
    # (no outside bits), so IS stays 1: DS = 24.5
    xy = straight(100) + [(50.0, 0.5 * j) for j in range(1, 61)]
    res = score_episode(make_log(xy, ((0.0, 0.0), (200.0, 0.0)), termination="route_deviation"))
    assert (res.rc, res.is_, res.ds) == (24.5, 1.0, 24.5)
    assert res.infractions == ()


def test_driving_against_traffic_and_a_sidewalk_excursion():
    # wrong lane (bit 2) on the steps passing points 20..39, off every lane (bit 1) on those
    # passing points 60..69: 30 m of 100 m advanced -> IS 0.7, DS 70; one outside-lanes entry
    xy = straight(201)
    flags = [2 if 20 < x <= 40 else 1 if 60 < x <= 70 else 0 for x, _ in xy]
    res = score_episode(make_log(xy, ROUTE, outside=flags, termination="completed"))
    assert res.outside_lanes_pct == pytest.approx(30.0)
    assert (res.rc, res.is_, res.ds) == (100.0, 0.7, 70.0)
    assert [(str(i.kind), round(i.factor, 6)) for i in res.infractions] == [("outside_route_lanes", 0.7)]


def test_no_outside_entry_without_advance_off_the_lanes():
    # four static collisions 10 m apart give IS 0.65^4 = 0.178506 and no outside-lanes entry
    evs = tuple(contact("collision_static", i, "roadside") for i in (20, 40, 60, 80))
    res = score_episode(make_log(straight(201), ROUTE, events=evs, termination="completed"))
    assert res.is_ == 0.178506
    assert [str(i.kind) for i in res.infractions] == ["collision_static"] * 4


def test_empty_log_scores_zero():
    log = make_log([], ROUTE, termination="sim_error")
    res = score_episode(log)
    assert (res.rc, res.is_, res.ds, res.duration) == (0.0, 1.0, 0.0, 0.0)



def test_step_budget_is_the_route_timeout_plus_a_margin():
    # int(0.8 * 100 + 5) = 85 s, plus 10 s, at 20 Hz, plus 10 steps
    assert LB1.time_budget(100.0) == 85.0
    assert LB1.max_steps(100.0, 0.05) == int(95.0 / 0.05) + 10 == 1910


# ------------------------------------------------------------------ the results file
def test_leaderboard_checkpoint():
    recs = tiny() + [rec("B", "r4", "misleading", 0, 30, 100, 0.3,
                         infractions=(("collision_vehicle", 0.6), ("red_light", 0.7),
                                      ("outside_route_lanes", 0.3 / 0.42)))]
    cp = leaderboard_checkpoint(recs, "B", "misleading")
    assert set(cp) == {"_checkpoint", "entry_status", "eligible", "sensors", "values", "labels"}
    # r1 k1 crashed ("boom": the agent's code raised): 'Agent crashed', still eligible
    assert cp["entry_status"] == "Finished with agent errors" and cp["eligible"] is True
    assert cp["sensors"] == []
    c = cp["_checkpoint"]
    assert set(c) == {"global_record", "progress", "records"}
    assert c["progress"] == [7, 7] and len(c["records"]) == 7
    recs_by_id = {r["route_id"]: r for r in c["records"]}
    assert [r["index"] for r in c["records"]] == list(range(7))
    first = c["records"][0]
    assert set(first) == {"route_id", "index", "status", "infractions", "scores", "meta"}
    assert set(first["infractions"]) == {
        "collisions_layout", "collisions_pedestrian", "collisions_vehicle", "outside_route_lanes",
        "red_light", "route_dev", "route_timeout", "stop_infraction", "vehicle_blocked"}
    assert set(first["scores"]) == {"score_route", "score_penalty", "score_composed"}
    assert set(first["meta"]) == {"route_length", "duration_game", "duration_system"}

    r1 = recs_by_id["RouteScenario_r1_misleading_0"]
    assert r1["status"] == "Failed - Agent deviated from the route"
    assert r1["infractions"]["route_dev"] == ["Agent deviated from the route"]
    assert recs_by_id["RouteScenario_r1_misleading_1"]["status"] == "Failed - Agent crashed"
    # no log: what the leaderboard writes for a route whose criteria recorded nothing
    assert recs_by_id["RouteScenario_r1_misleading_1"]["scores"] == {
        "score_route": 0.0, "score_penalty": 1.0, "score_composed": 0.0}
    assert recs_by_id["RouteScenario_r2_misleading_1"]["status"] == "Failed - Agent timed out"
    assert recs_by_id["RouteScenario_r2_misleading_1"]["infractions"]["route_timeout"] == ["Route timeout."]
    assert recs_by_id["RouteScenario_r3_misleading_0"]["status"] == "Completed"
    r4 = recs_by_id["RouteScenario_r4_misleading_0"]
    assert r4["scores"] == {"score_route": 100.0, "score_penalty": 0.3, "score_composed": 30.0}
    assert len(r4["infractions"]["collisions_vehicle"]) == 1 and len(r4["infractions"]["red_light"]) == 1
    # the outside-lanes entry comes from the stored infraction (1 - 0.3 / 0.42 = 28.57 %) ...
    assert "28.57%" in r4["infractions"]["outside_route_lanes"][0]
    # ... never from IS arithmetic: r3 k0 has IS 0.9 but no such infraction, so no entry
    assert recs_by_id["RouteScenario_r3_misleading_0"]["infractions"]["outside_route_lanes"] == []

    g = c["global_record"]
    assert g["index"] == -1 and g["route_id"] == -1 and g["status"] == "Failed"
    assert set(g) >= {"route_id", "index", "status", "infractions", "scores", "meta"}
    # means over every route, the crashed one (DS 0, IS 1) included
    assert g["scores"]["score_composed"] == pytest.approx((20 + 0 + 10 + 50 + 90 + 45 + 30) / 7)
    assert g["scores"]["score_penalty"] == pytest.approx((1 + 1 + 1 + 1 + 0.9 + 0.9 + 0.3) / 7)
    # rates: sum over routes of count / (RC / 100 x 0.5 km): route deviations on r1 k0
    # (RC 20: 1 / 0.1), r2 k0 (RC 10: 1 / 0.05), r3 k1 (RC 50: 1 / 0.25); r4's collision (RC 100)
    assert g["infractions"]["route_dev"] == pytest.approx(10 + 20 + 4, abs=1e-6)
    assert g["infractions"]["collisions_vehicle"] == pytest.approx(2.0, abs=1e-6)
    assert ["RouteScenario_r1_misleading_1", 1, "Failed - Agent crashed"] in g["meta"]["exceptions"]
    assert g["meta"]["total_length"] == 3000.0 and g["meta"]["duration_game"] == 360.0  # crashed: 0
    assert g["meta"]["duration_system"] == -1
    assert len(cp["values"]) == len(cp["labels"]) == 12
    assert cp["labels"][0] == "Avg. driving score"
    assert cp["values"][0] == f"{g['scores']['score_composed']:.3f}"
    json.loads(dumps_json(cp))  # serialisable, no NaN

    # without the crash: deviations and timeouts name the agent
    ok = [r for r in recs if r.status == "done"]
    assert leaderboard_checkpoint(ok, "B", "misleading")["entry_status"] == "Finished with agent errors"
    done = [rec("B", "r3", "misleading", 0, 90, 100, 0.9)]
    assert leaderboard_checkpoint(done, "B", "misleading")["entry_status"] == "Finished"

    blocked = [EpisodeRecord("X", "r", "noise", 0, 1, "done", termination="agent_blocked",
                             termination_class="TO", is_=1.0)]
    cb = leaderboard_checkpoint(blocked, "X", "noise")["_checkpoint"]["records"][0]
    assert cb["status"] == "Failed - Agent got blocked" and len(cb["infractions"]["vehicle_blocked"]) == 1


def test_a_route_with_rc_0_adds_no_rate():
    # r1: RC 0 with a collision and a deviation: the final leaderboard-1.0 code skips the route
    # (the 0.001 km floor it dropped made each 1 / 0.001 = 1,000 per km); r2: RC 50 of 0.5 km,
    # 1 / 0.25 km = 4 per km each
    recs = [rec("X", "r1", "noise", 0, 0, 0, 0.6, "RD", infractions=(("collision_vehicle", 0.6),)),
            rec("X", "r2", "noise", 0, 30, 50, 0.6, "RD", infractions=(("collision_vehicle", 0.6),))]
    g = leaderboard_checkpoint(recs, "X", "noise")["_checkpoint"]["global_record"]
    assert g["infractions"]["collisions_vehicle"] == 4.0 and g["infractions"]["route_dev"] == 4.0


def test_the_route_length_is_the_key_points():
    # r1's key points (0, 0) -> (30, 40) -> (30, 100): 50 + 60 = 110 m (its lanes: 500 m); r2's
    # are not known: its record's 500 m
    recs = [rec("X", "r1", "noise", 0, 50, 50, 1.0, "RD"), rec("X", "r2", "noise", 0, 100, 100, 1.0)]
    cp = LB1.leaderboard_file(recs, "X", "noise", key_points={"r1": KEY_POINTS["r1"]})
    assert [r["meta"]["route_length"] for r in cp["_checkpoint"]["records"]] == [110.0, 500.0]
    g = cp["_checkpoint"]["global_record"]
    assert g["meta"]["total_length"] == 610.0
    assert g["infractions"]["route_dev"] == round(1 / (0.5 * 0.110), 6)
    # without key points, the records' lengths
    plain = leaderboard_checkpoint(recs, "X", "noise")["_checkpoint"]["global_record"]
    assert plain["meta"]["total_length"] == 1000.0 and plain["infractions"]["route_dev"] == 4.0


def _crashed(route: str, message: str) -> EpisodeRecord:
    return replace(rec("X", route, "noise", 0, status="crashed"), message=message)


def test_a_crashed_episode_is_the_agents_unless_the_simulation_failed():
    agent = [rec("X", "r1", "noise", 0, 100, 100, 1.0),
             _crashed("r2", "ValueError: bad shape at my_policy.py:3"),
             _crashed("r3", "AgentTimeout: agent did not answer within 5 s")]
    cp = leaderboard_checkpoint(agent, "X", "noise")
    assert [r["status"] for r in cp["_checkpoint"]["records"]] == [
        "Completed", "Failed - Agent crashed", "Failed - Agent crashed"]
    assert (cp["entry_status"], cp["eligible"]) == ("Finished with agent errors", True)
    for why in ("SimulatorError: TraCIException: no network at backend.py:64",
                "WorkerDied: the worker process died (exit code -9)"):
        cp = leaderboard_checkpoint([*agent, _crashed("r4", why)], "X", "noise")
        assert cp["_checkpoint"]["records"][-1]["status"] == "Failed - Simulation crashed"
        assert (cp["entry_status"], cp["eligible"]) == ("Crashed", False)


def _by_key(logs: dict):
    """The ``logs`` argument of the results file: a record's log in ``logs`` (by its key)."""
    return lambda r: logs.get((r.agent, r.route_id, r.family, r.k, r.seed))


def _partial(n: int, xy=None, **kw) -> EpisodeLog:
    """An agent's crash after ``n`` steps on :data:`ROUTE`: the log of the steps up to it."""
    log = make_log(xy or straight(n), ROUTE, termination="agent_error", **kw)
    return replace(log, message="RuntimeError: boom at a.py:9")


def test_an_agent_crash_keeps_the_partial_scores_of_its_log():
    """A crashed episode stored with the log of its steps up to the crash has, in the results
    file, the RC, IS, infractions and duration the criteria had computed then (as the
    leaderboard keeps them), status 'Failed - Agent crashed'; one without a log scores 0, 1, 0;
    icrsumo's own records are not changed."""
    import lb1_reference

    # 81 steps: the ego centre at x = 40.25 (RC 40 %), a counted vehicle collision (0.6) and
    # 5 m of route advance outside the lanes of the 40 m made (x 0.875 on IS)
    log = _partial(81, events=(contact("collision_vehicle", 30, "veh1"),),
                   outside=[1 if 20 < i <= 30 else 0 for i in range(81)])
    crashed = replace(_crashed("r2", log.message), length=300.0)
    recs = [rec("X", "r1", "noise", 0, 100, 100, 1.0), crashed, _crashed("r3", "ValueError: early at a.py:1")]
    logs = {("X", "r2", "noise", 0, 7): log}
    mine = leaderboard_checkpoint(recs, "X", "noise", KEY_POINTS, logs=_by_key(logs))
    assert lb1_reference.differences(mine, lb1_reference.leaderboard_file(recs, KEY_POINTS, logs)) == []
    r1, r2, r3 = mine["_checkpoint"]["records"]
    res = LB1.score(log)
    assert (res.rc, res.is_) == (40.0, pytest.approx(0.6 * 0.875))
    assert r2["scores"] == {"score_route": res.rc, "score_penalty": res.is_, "score_composed": res.ds}
    assert r2["status"] == "Failed - Agent crashed" and r2["meta"]["duration_game"] == 4.0
    assert [len(r2["infractions"][k]) for k in ("collisions_vehicle", "outside_route_lanes")] == [1, 1]
    assert sum(map(len, r2["infractions"].values())) == 2
    assert r3["scores"] == {"score_route": 0.0, "score_penalty": 1.0, "score_composed": 0.0}
    assert (mine["entry_status"], mine["eligible"]) == ("Finished with agent errors", True)
    assert mine["_checkpoint"]["global_record"]["scores"]["score_route"] == pytest.approx((100 + 40 + 0) / 3)
    assert mine["_checkpoint"]["global_record"]["meta"]["duration_game"] == 64.0
    assert recs[1] == crashed  # the stored record keeps no scores
    # rescored by rules that end the route inside the log (here 1.0's deviation: it left the
    # route before the crash), the route has that ending's status, as compute_route_statistics
    # gives it
    off = _partial(0, xy=straight(40) + [(19.75, 0.5 * j) for j in range(1, 80)])
    logs = {("X", "r2", "noise", 0, 7): off}
    mine = leaderboard_checkpoint(recs, "X", "noise", KEY_POINTS, logs=_by_key(logs))
    assert mine["_checkpoint"]["records"][1]["status"] == "Failed - Agent deviated from the route"
    assert lb1_reference.differences(mine, lb1_reference.leaderboard_file(recs, KEY_POINTS, logs)) == []


def test_exceptions_are_listed_only_when_a_route_failed():
    g = leaderboard_checkpoint([rec("X", "r1", "noise", 0, 100, 100, 1.0)], "X", "noise")["_checkpoint"][
        "global_record"]
    assert g["status"] == "Completed" and "exceptions" not in g["meta"]
    assert g["scores_std_dev"] == {"score_route": "NaN", "score_penalty": "NaN", "score_composed": "NaN"}


# ------------------------------------------------------------------ against the transcription
def _agree(log) -> None:
    """icrsumo's lb1 scores and termination agree with the leaderboard's code transcribed in
    tests/lb1_reference.py within 1e-4."""
    import lb1_reference

    ref = lb1_reference.score(log)
    res = score_episode(log)
    assert res.rc == pytest.approx(ref["score_route"], abs=1e-4)
    assert res.is_ == pytest.approx(ref["score_penalty"], abs=1e-4)
    assert res.ds == pytest.approx(ref["score_composed"], abs=1e-4)
    if ref["ended"] is not None:
        assert res.termination == ref["ended"]


CASES = ["clean", "contacts", "places", "outside", "wrong_turn", "parallel", "short"]


@pytest.mark.parametrize("case", CASES)
def test_hand_built_logs_agree_with_the_leaderboard_transcription(case):
    xy = straight(201)
    logs = {
        "clean": make_log(xy, ROUTE, termination="completed"),
        "contacts": make_log(xy, ROUTE, termination="completed", events=tuple(
            contact("collision_vehicle", i, "veh1") for i in [*range(20, 30), 100, 140])),
        "places": make_log(xy, ROUTE, termination="completed", events=(
            contact("collision_vehicle", 20, "a"), contact("collision_vehicle", 24, "b"),
            contact("collision_static", 60, "roadside"), contact("collision_static", 70, "roadside"),
            Event("red_light", 3.0, 0.0, "tl"))),
        "outside": make_log(xy, ROUTE, termination="completed",
                            outside=[2 if 20 < x <= 40 else 1 if 60 < x <= 70 else 0 for x, _ in xy]),
        "wrong_turn": make_log(straight(100) + [(50.0, 0.5 * j) for j in range(1, 61)],
                               ((0.0, 0.0), (200.0, 0.0)), termination="route_deviation"),
        "parallel": make_log(straight(120, y=20.0), ROUTE, termination="route_deviation"),
        "short": make_log(straight(191) + [(95.25, 0.0)] * 1511, ROUTE, speed=[10.0] * 191 + [0.0] * 1511),
    }
    _agree(logs[case])


# ------------------------------------------------------------------ the results file, transcribed
KEY_POINTS = {"r1": [(0.0, 0.0), (30.0, 40.0), (30.0, 100.0)], "r2": [(5.0, 5.0), (5.0, 305.0)]}
COLLISION = ("collision_vehicle", 0.6)


def _sim_error(route: str, k: int, rc: float) -> EpisodeRecord:
    """SUMO died in the episode: a finished episode ended by sim_error, scored on its log."""
    return replace(rec("X", route, "noise", k, rc, rc, 1.0, "TO"), termination="sim_error")


SETS = {
    "rc0_with_infractions": [rec("X", "r1", "noise", 0, 0, 0, 0.6, "RD", infractions=(COLLISION,)),
                             rec("X", "r2", "noise", 0, 42, 70, 0.6, "TO", infractions=(COLLISION,))],
    "rc100": [rec("X", "r1", "noise", 0, 42, 100, 0.42, infractions=(COLLISION, ("red_light", 0.7))),
              rec("X", "r1", "noise", 1, 100, 100, 1.0)],
    "agent_crash": [rec("X", "r1", "noise", 0, 100, 100, 1.0), _crashed("r2", "RuntimeError: boom at a.py:9"),
                    rec("X", "r3", "noise", 0, 25, 25, 1.0, "RD")],
    "simulation_crash": [rec("X", "r1", "noise", 0, 100, 100, 1.0), _crashed("r2", "WorkerDied: code -11"),
                         rec("X", "r3", "noise", 0, 25, 25, 1.0, "RD")],
    "sim_error_episode": [rec("X", "r1", "noise", 0, 100, 100, 1.0), _sim_error("r2", 0, 35.5)],
    "several_routes": [rec("X", "r1", "noise", 0, 60, 100, 0.6, infractions=(COLLISION,)),
                       rec("X", "r1", "noise", 1, 12.5, 25, 0.5, "RD",
                           infractions=(("collision_pedestrian", 0.5),)),
                       rec("X", "r2", "noise", 0, 56, 80, 0.7, "TO", infractions=(("red_light", 0.7),)),
                       rec("X", "r3", "noise", 0, 80, 100, 0.8, infractions=(("stop_sign", 0.8),)),
                       rec("X", "r3", "noise", 1, 40, 50, 0.8, "RD",
                           infractions=(("outside_route_lanes", 0.8),)),
                       replace(rec("X", "r4", "noise", 0, 0, 0, 1.0, "TO"), termination="agent_blocked")],
}


@pytest.mark.parametrize("case", SETS)
def test_results_file_agrees_with_the_leaderboard_transcription(case):
    import lb1_reference

    recs = SETS[case]
    mine = leaderboard_checkpoint(recs, "X", "noise", KEY_POINTS)
    ref = lb1_reference.leaderboard_file(recs, KEY_POINTS)
    assert lb1_reference.differences(mine, ref) == []
    if case == "simulation_crash":
        # the leaderboard's run ends at r2 with no global record; icrsumo writes every route
        assert ref["_checkpoint"]["global_record"] == {} and len(ref["_checkpoint"]["records"]) == 2
        assert len(mine["_checkpoint"]["records"]) == 3 and mine["_checkpoint"]["global_record"]["scores"]


def _random_partial(rng: random.Random) -> EpisodeLog:
    """A random agent crash's log on :data:`ROUTE`: straight on, or leaving it sideways, with
    random contacts and steps outside the lanes (some of them end the route before the crash)."""
    n = rng.randint(1, 260)
    turn = rng.choice([n, rng.randint(0, n)])
    x = 0.25 + 0.5 * turn
    xy = straight(turn) + [(x, 0.5 * j) for j in range(1, n - turn + 1)]
    events = [contact(rng.choice(["collision_vehicle", "collision_static", "collision_pedestrian"]),
                      rng.randrange(n), rng.choice(["a", "b"])) for _ in range(rng.choice([0, 1, 3]))]
    outside = [int(rng.random() < 0.2) for _ in range(n)]
    return _partial(n, xy=xy, events=tuple(sorted(events, key=lambda e: e.t)), outside=outside)


def _random_record(rng: random.Random, route: str, k: int, logs: dict | None = None) -> EpisodeRecord:
    """A consistent random record: its termination, RC, counted infractions and IS their product;
    an agent's crash may have a partial log (put in ``logs``)."""
    end = rng.choice(["completed", "route_deviation", "route_timeout", "agent_blocked", "stuck", "sim_error",
                      "crash_agent", "crash_sim", "crash_log"])
    if end == "crash_log" and logs is not None:
        logs[("X", route, "noise", k, 7)] = _random_partial(rng)
        crashed = _crashed(route, "RuntimeError: boom at a.py:9")
        return replace(crashed, k=k, length=round(rng.uniform(50, 900), 2))
    if end.startswith("crash"):
        why = "SimulatorError: gone" if end == "crash_sim" else "KeyError: 'x' at a.py:1"
        return replace(_crashed(route, why), k=k)
    rc = 100.0 if end == "completed" else rng.choice([0.0, 0.0, round(rng.uniform(0, 99), 4)])
    kinds = [("collision_pedestrian", 0.5), ("collision_vehicle", 0.6), ("collision_static", 0.65),
             ("red_light", 0.7), ("stop_sign", 0.8), ("outside_route_lanes", round(rng.uniform(0.1, 1), 6))]
    infr = tuple(rng.choice(kinds) for _ in range(rng.choice([0, 0, 1, 2, 4])))
    is_ = math.prod(f for _, f in infr)
    r = rec("X", route, "noise", k, rc * is_, rc, is_, infractions=infr)
    return replace(r, termination=end, length=round(rng.uniform(50, 900), 2),
                   duration=round(rng.uniform(0, 300), 2))


def test_random_results_files_agree_with_the_leaderboard_transcription():
    """500 random sets of 1 to 12 records (some routes with key points), no simulation crash
    among them or one: icrsumo's file and the transcription's agree."""
    import lb1_reference

    rng = random.Random(47)
    for _ in range(500):
        routes = [f"r{i}" for i in range(rng.randint(1, 6))]
        logs: dict = {}
        recs = [_random_record(rng, rid, k, logs) for rid in routes for k in range(rng.randint(1, 2))]
        key_points = {rid: [(rng.uniform(0, 500), rng.uniform(0, 500)) for _ in range(rng.randint(2, 5))]
                      for rid in routes if rng.random() < 0.7}
        mine = leaderboard_checkpoint(recs, "X", "noise", key_points, logs=_by_key(logs))
        assert lb1_reference.differences(mine, lb1_reference.leaderboard_file(recs, key_points, logs)) == []


def test_a_sustained_scrape_is_charged_again_every_3_m():
    """The sensors log a static-layout contact on every step off the drivable area; CollisionTest
    (the static layout is never the remembered actor) charges it again once the ego is more
    than 3 m from every place it charged: 10 m of scrape at 0.5 m a step, 3 charges."""
    evs = tuple(contact("collision_static", i, "roadside") for i in range(20, 41))
    log = make_log(straight(120), ROUTE, events=evs)
    got = LB1.penalised_events(log)
    assert [round(e.x, 2) for e in got] == [10.25, 13.75, 17.25]
    assert [i.factor for i in LB1.penalised_infractions(log)] == [0.65] * 3
    assert score_episode(log).is_ == pytest.approx(0.65 ** 3)
