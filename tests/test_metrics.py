"""Leaderboard 1.0 scoring (icrsumo.metrics) on hand-built logs, no SUMO.

Logs are built as in tests/test_termination.py: 20 Hz steps, the ego centre at x = 0.25 + 0.5 i
on step i (t = 0.05 i), a straight 100 m route along +x unless stated. Expected values are
worked out in the comments from the leaderboard's rules (statistics_manager.py,
CollisionTest, OutsideRouteLanesTest).
"""

from __future__ import annotations

import pytest
from test_termination import make_log, straight

from icrsumo.metrics import PENALTIES, SCORINGS, Scoring, counted_collisions, register_scoring, score_episode
from icrsumo.types import Event

ROUTE = ((0.0, 0.0), (100.0, 0.0))


def contact(kind: str, i: int, other: str) -> Event:
    return Event(kind, round(0.05 * i, 3), 0.0, other, 0.25 + 0.5 * i, 0.0)


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
    # as in test_termination: deviation at (50, 30) with RC 24.5 %; the lane taken is legal
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


def test_scoring_registry_refuses_duplicates_and_unknown_names():
    assert "lb1" in SCORINGS
    with pytest.raises(ValueError, match="registered already"):
        register_scoring(Scoring("lb1", "again", SCORINGS["lb1"].score))
    with pytest.raises(ValueError, match="unknown scoring"):
        score_episode(make_log(straight(3), ROUTE), "lb9")


# ------------------------------------------------------------------ Leaderboard 2.0 (lb2)
def lb2_log(xy, *, speed=None, traffic=10.0, limit=10.0, outside=None, events=(), termination="completed"):
    """A log with 2.0's columns: the other vehicles' mean speed and the lane's speed limit (m/s)."""
    from dataclasses import replace

    log = make_log(xy, ROUTE, speed=speed, outside=outside, events=events, termination=termination)
    return replace(log, traffic_speed=(traffic,) * len(xy), speed_limit=(limit,) * len(xy))


def test_lb2_minimum_speed_checkpoints():
    # 5 m/s against traffic at 10 m/s (0.25 m per step, x = 0.25 + 0.25 i): 4 checkpoints of
    # 25 m; a checkpoint closes once the route advance since the last one exceeds 25 m (points
    # 26, 52, 78) and at the end (100 % > 95 %): four times 50 % -> 1 - 0.3 x 0.5 = 0.85 each
    xy = [(0.25 + 0.25 * i, 0.0) for i in range(402)]
    res = score_episode(lb2_log(xy, speed=[5.0] * len(xy)), "lb2")
    assert [str(i.kind) for i in res.infractions] == ["min_speed"] * 4
    assert res.is_ == pytest.approx(0.85 ** 4, abs=1e-6) and res.rc == 100.0
    # as fast as the traffic: no infraction; lb1 has no such test
    same = lb2_log(xy, speed=[10.0] * len(xy))
    assert score_episode(same, "lb2").infractions == ()
    assert score_episode(lb2_log(xy, speed=[5.0] * len(xy)), "lb1").infractions == ()


def test_lb2_route_timeout_grows_with_the_route_advance():
    # 2.0: 300 s, plus each metre of advance at 10 % of the speed limit (10 m/s -> 1 s per m);
    # 50 points passed -> 350 s; 1.0's budget for 100 m is int(85) s
    from icrsumo.termination import LB2_RULES, DenseRoute, TerminationMonitor

    mon = TerminationMonitor(DenseRoute.from_polyline(ROUTE), 0.0, LB2_RULES)
    for i, (x, y) in enumerate(straight(101)):
        mon.locate(x, y)
        mon.update(0.05 * i, 10.0, 0, (), 10.0, 10.0)
    assert mon.timeout == pytest.approx(350.0)


def test_lb2_collisions_ignore_a_standing_ego_and_keep_one_place():
    # veh1 at step 20 counts (x = 10.25); veh2 at step 28 (4 m away, within 2.0's 5 m) is
    # ignored; veh3 at step 40 while the ego stands (speed 0.05) is ignored and remembers
    # nothing; veh4 at step 60 (20 m on) counts: 0.6^2
    speed = [10.0] * 201
    speed[40] = 0.05
    evs = (contact("collision_vehicle", 20, "veh1"), contact("collision_vehicle", 28, "veh2"),
           contact("collision_vehicle", 40, "veh3"), contact("collision_vehicle", 60, "veh4"))
    res = score_episode(lb2_log(straight(201), speed=speed, events=evs), "lb2")
    assert [i.other for i in res.infractions if i.kind == "collision_vehicle"] == ["veh1", "veh4"]
    # 1.0 counts veh3 (no speed rule) and veh2 is 4 m > 3 m away: all four
    assert len(score_episode(lb2_log(straight(201), speed=speed, events=evs), "lb1").infractions) == 4


def test_lb2_reads_its_own_outside_bits():
    # bits 4 / 8 are 2.0's (lanes left beyond width / 2 + 0.5 m); bit 1 alone is 1.0's
    xy = straight(201)
    flags = [4 if 20 < x <= 40 else 1 if 60 < x <= 70 else 0 for x, _ in xy]
    log = lb2_log(xy, outside=flags)
    assert score_episode(log, "lb2").outside_lanes_pct == pytest.approx(20.0)
    assert score_episode(log, "lb1").outside_lanes_pct == pytest.approx(10.0)


def test_rescoring_under_rules_that_end_sooner_is_exact_and_later_is_flagged():
    from icrsumo.metrics import ended_by
    from icrsumo.termination import LB1_RULES, LB2_RULES

    # recorded until 2.0's blocked rule (moving to step 100, then standing): 1.0's route
    # timeout (85 s for 100 m) ends it sooner, at 85.05 s: the cut log is 1.0's run
    n = 3702
    xy = straight(101) + [(50.25, 0.0)] * (n - 101)
    log = lb2_log(xy, speed=[10.0] * 101 + [0.0] * (n - 101), termination="agent_blocked")
    cut, exact = ended_by(log, LB1_RULES)
    assert exact and cut.termination == "route_timeout" and cut.t[-1] == 85.05
    assert score_episode(log, "lb1").termination == "route_timeout"
    # the other way: 2.0's rules would have run past 85 s, so the cut log is not their run
    short, exact = ended_by(cut, LB2_RULES)
    assert not exact and short is cut


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
