"""Leaderboard 2.0's scoring (icrsumo.scoring.lb2) on hand-built logs and records, no SUMO
(logs as tests/hand_logs.py builds them, with 2.0's columns)."""

from __future__ import annotations

from dataclasses import replace

import pytest
from hand_logs import contact, lb2_log, straight  # tests/ is on pytest's pythonpath
from records_example import rec

from icrsumo.scoring import score_episode
from icrsumo.scoring.lb2 import LB2, leaderboard_checkpoint_lb2


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


def test_step_budget_bounds_the_growing_timeout():
    # 300 s plus 100 m at 10 % of 1 m/s (1000 s), plus 10 s, at 20 Hz, plus 10 steps
    assert LB2.time_budget(100.0) == 1300.0
    assert LB2.max_steps(100.0, 0.05) == int(1310.0 / 0.05) + 10 == 26210


# ------------------------------------------------------------------ the results file
def test_leaderboard_2_results_file():
    recs = [rec("B", "r1", "misleading", 0, 100, 100, 1.0),                       # Perfect
            rec("B", "r2", "misleading", 0, 85, 100, 0.85, infractions=(("min_speed", 0.85),)),
            rec("B", "r3", "misleading", 0, 40, 50, 0.8, "RD",
                infractions=(("outside_route_lanes", 0.8),), outside_m=50.0),
            replace(rec("B", "r4", "misleading", 0, status="crashed"),  # SUMO did not start
                    message="SimulatorError: TraCIException: no network at backend.py:64")]
    cp = leaderboard_checkpoint_lb2(recs, "B", "misleading")
    rs = cp["_checkpoint"]["records"]
    assert [r["status"] for r in rs] == ["Perfect", "Completed", "Failed - Agent deviated from the route",
                                         "Failed - Simulation crashed"]
    assert rs[1]["infractions"]["min_speed_infractions"] == [
        "Average speed is 50.00% of the surrounding traffic's one"]
    # the metres off the lanes, where 2.0's global statistics read them
    assert rs[2]["infractions"]["outside_route_lanes"][0].split(" ")[8] == "50.000"
    g = cp["_checkpoint"]["global_record"]
    assert g["status"] == "Failed"
    assert g["scores_mean"]["score_composed"] == round((100 + 85 + 40 + 0) / 4, 6)
    # pooled: counts over the km driven (0.5 + 0.5 + 0.25 + 0 km); outside lanes in km
    assert g["infractions"]["route_dev"] == round(1 / 1.25, 3)
    assert g["infractions"]["outside_route_lanes"] == 0.05
    assert len(cp["values"]) == len(cp["labels"]) == 15
    assert cp["entry_status"] == "Crashed" and cp["eligible"] is False


def test_an_agent_crash_keeps_its_partial_scores_in_the_2_0_file():
    """As in 1.0's file: a crashed episode stored with the log of its steps up to the crash has
    the RC, IS and infractions 2.0's criteria had computed then; without a log, as stored."""
    log = replace(lb2_log(straight(81), events=(contact("collision_vehicle", 30, "veh1"),),
                          termination="agent_error"), message="RuntimeError: boom at a.py:9")
    crashed = replace(rec("B", "r2", "noise", 0, status="crashed"), message=log.message)
    bare = replace(rec("B", "r3", "noise", 0, status="crashed"), message="ValueError: early at a.py:1")
    recs = [rec("B", "r1", "noise", 0, 100, 100, 1.0), crashed, bare]
    logs = {("B", "r2", "noise", 0, 7): log}
    cp = LB2.leaderboard_file(recs, "B", "noise", logs=lambda r: logs.get((r.agent, r.route_id, r.family, r.k,
                                                                          r.seed)))
    r1, r2, r3 = cp["_checkpoint"]["records"]
    res = LB2.score(log)
    assert res.rc == 40.0 and res.is_ == pytest.approx(0.6)
    assert r2["status"] == "Failed - Agent crashed"
    assert r2["scores"] == {"score_route": res.rc, "score_penalty": round(res.is_, 6),
                           "score_composed": round(res.ds, 6)}
    assert len(r2["infractions"]["collisions_vehicle"]) == 1
    assert r3["status"] == "Failed - Agent crashed" and r3["scores"]["score_route"] == 0.0
    assert cp["entry_status"] == "Finished"
    # without the logs, as stored
    plain = LB2.leaderboard_file(recs, "B", "noise")["_checkpoint"]["records"]
    assert plain[1]["scores"]["score_route"] == 0.0
