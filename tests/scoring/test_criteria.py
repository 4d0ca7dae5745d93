"""The route criteria monitor (icrsumo.scoring.criteria) on hand-built logs, no SUMO.

Logs as tests/hand_logs.py builds them. Expected values are worked out in the comments from
the rules in icrsumo/scoring/criteria.py (RouteCompletionTest, InRouteTest,
OutsideRouteLanesTest, ActorSpeedAboveThresholdTest, the route timeouts) under Leaderboard
1.0's rules unless a test names 2.0's.
"""

from __future__ import annotations

import pytest
from hand_logs import DT, ROUTE, contact, lb2_log, make_log, straight  # tests/ is on pytest's pythonpath

from icrsumo.core.types import Event
from icrsumo.scoring import score_episode
from icrsumo.scoring.criteria import (
    BLOCKED_S,
    DEVIATION_M,
    TerminationMonitor,
    ended_by,
    replay,
    route_timeout,
    run_monitor,
)
from icrsumo.scoring.lb1 import LB1, LB1_RULES
from icrsumo.scoring.lb2 import LB2_RULES
from icrsumo.scoring.route import DenseRoute


def lb1_monitor(log):
    """The monitor run over ``log`` by Leaderboard 1.0's rules, and its decision."""
    return run_monitor(log, LB1_RULES)


def test_constants_and_the_truncated_timeout():
    assert DEVIATION_M == 30.0 and BLOCKED_S == 180.0
    assert route_timeout(100.0) == 85.0          # int(0.8 * 100 + 5)
    assert route_timeout(100.6) == 85.0          # int(85.48): truncated to whole seconds
    assert route_timeout(0.0) == 5.0


def test_completion_needs_more_than_99_percent_and_10_m():
    # 100 m route: RC > 99 % needs point 100 passed (x > 100: step 200, x = 100.25, t = 10.0),
    # and the goal (100, 0) is then 0.25 m away; the old rule (99 % or 10 m) ended at x = 90.
    # RouteCompletionTest reports the success on the next tick: the route ends at t = 10.05
    log = make_log(straight(220), ((0.0, 0.0), (100.0, 0.0)), termination="completed")
    mon, end = lb1_monitor(log)
    assert end == ("completed", 10.05)
    assert mon.completion_pct == 100.0


def test_the_tick_after_completion_counts_and_a_log_ending_on_the_completing_tick_scores_alike():
    """The step after the completing one is part of the route: a collision in it is charged.
    A log recorded by the loop's first rules (ending on the completing step) is scored as
    completed, as it was recorded."""
    route = ((0.0, 0.0), (100.0, 0.0))
    hit = (contact("collision_vehicle", 201, "veh9"),)
    log = make_log(straight(202), route, termination="completed", events=hit)
    res = score_episode(log)
    assert (res.termination, res.rc, res.is_) == ("completed", 100.0, 0.6)
    old = make_log(straight(201), route, termination="completed")
    assert ended_by(old, LB1.rules) == (old, True)
    assert (score_episode(old).termination, score_episode(old).rc) == ("completed", 100.0)


def test_finishing_5_m_short_of_the_end_is_not_completion():
    # stops at x = 95.25 (step 190) and stands: point 95 passed -> RC 95 %; never blocked before
    # the route timeout: int(0.8 * 100 + 5) = 85 s, reached at the first t > 85.0, i.e. 85.05 s
    n = 1702
    xy = straight(191) + [(95.25, 0.0)] * (n - 191)
    speed = [10.0] * 191 + [0.0] * (n - 191)
    mon, end = lb1_monitor(make_log(xy, ((0.0, 0.0), (100.0, 0.0)), speed=speed))
    assert end == ("route_timeout", 85.05)
    assert mon.completion_pct == pytest.approx(95.0)


def test_blocked_counts_from_the_last_step_at_or_above_0_1_m_s():
    # 300 m route (timeout int(245) = 245 s); moving until step 100 (t = 5.0), then 0.05 m/s:
    # blocked at the first t with t - 5.0 > 180, i.e. 185.05 s
    n = 3702
    xy = straight(101) + [(50.25, 0.0)] * (n - 101)
    speed = [10.0] * 101 + [0.05] * (n - 101)
    _, end = lb1_monitor(make_log(xy, ((0.0, 0.0), (300.0, 0.0)), speed=speed))
    assert end == ("agent_blocked", 185.05)


def test_a_wrong_turn_into_a_legal_lane_is_a_deviation_at_30_m():
    # along x to (50, 0), then up +y at x = 50; the nearest of the next route points is (50, 0),
    # 30 m or more away once y >= 30 -> route deviation on that step; RC: point 49 passed
    # (x = 50 is not > 50), so 49 of 200 m = 24.5 %
    xy = straight(100) + [(50.0, 0.5 * j) for j in range(1, 70)]
    mon, end = lb1_monitor(make_log(xy, ((0.0, 0.0), (200.0, 0.0))))
    assert end[0] == "route_deviation"
    assert xy[log_index(end[1])] == (50.0, 30.0)
    assert mon.completion_pct == pytest.approx(24.5)
    assert mon.outside_pct == 0.0


def log_index(t: float) -> int:
    return round(t / DT)


def test_driving_15_m_off_the_route_for_30_percent_of_it_is_a_deviation():
    # parallel to a 100 m route at y = 20 (15 <= d < 30: not in the safe band): each advance of
    # the nearest route point is added; it is point 31 once x = 30.75 (step 61, t = 3.05), making
    # 31 m > 30 % of 100 m. RC there: point 30 passed (30.75 > 30, not > 31) -> 30 %
    mon, end = lb1_monitor(make_log(straight(120, y=20.0), ((0.0, 0.0), (100.0, 0.0))))
    assert end == ("route_deviation", 3.05)
    assert mon.completion_pct == pytest.approx(30.0)


def test_within_15_m_the_route_may_be_followed_off_centre():
    # 9 m off the centre line: never deviated, and the goal is 9.003 m away at x = 100.25 (< 10)
    _, end = lb1_monitor(make_log(straight(220, y=9.0), ((0.0, 0.0), (100.0, 0.0)),
                                  termination="completed"))
    assert end == ("completed", 10.05)  # reported on the tick after the completing one
    # 14.9 m off, stopping at x = 100.25: never deviated, but never within 10 m of the goal
    # either: the route times out
    xy = straight(201, y=14.9) + [(100.25, 14.9)] * 1501
    speed = [10.0] * 201 + [0.0] * 1501
    _, end = lb1_monitor(make_log(xy, ((0.0, 0.0), (100.0, 0.0)), speed=speed))
    assert end == ("route_timeout", 85.05)


def test_a_shortcut_through_a_junction_still_completes():
    # an L-shaped route (0,0) -> (50,0) -> (50,50); the ego cuts the corner on the diagonal from
    # (40, 0) to (50, 10), then goes up x = 50: progress catches up 2 points per step, nothing is
    # charged, and the route completes (100 m) once y > 50
    route = ((0.0, 0.0), (50.0, 0.0), (50.0, 50.0))
    xy = straight(80) + [(40.0 + 0.25 * j, 0.25 * j) for j in range(1, 41)] + \
        [(50.0, 10.0 + 0.5 * j) for j in range(1, 90)]
    mon, end = lb1_monitor(make_log(xy, route, termination="completed"))
    assert end[0] == "completed" and mon.completion_pct == 100.0 and mon.outside_pct == 0.0


def test_outside_lanes_counts_route_advance_on_flagged_steps():
    # 100 m route, flagged (wrong lane, bit 2) while 20 < x <= 40: the steps that pass points
    # 20..39 (x = k + 0.25) are flagged -> 20 m of 100 m advanced: 20 %
    xy = straight(220)
    flags = [2 if 20 < x <= 40 else 0 for x, _ in xy]
    mon, _ = lb1_monitor(make_log(xy, ((0.0, 0.0), (100.0, 0.0)), outside=flags, termination="completed"))
    assert (mon.outside_m, mon.driven_m) == (20.0, 100.0)
    assert mon.outside_pct == pytest.approx(20.0)


def test_standing_still_off_the_lanes_costs_nothing():
    # flagged only while standing (no route advance on those steps): 0 %
    xy = straight(41) + [(20.25, 0.0)] * 100 + [(20.25 + 0.5 * j, 0.0) for j in range(1, 170)]
    flags = [0] * 41 + [1] * 100 + [0] * 169
    mon, _ = lb1_monitor(make_log(xy, ((0.0, 0.0), (100.0, 0.0)), outside=flags))
    assert mon.outside_m == 0.0 and mon.outside_pct == 0.0


def test_ending_events_and_replay():
    xy = straight(10)
    log = make_log(xy, ((0.0, 0.0), (100.0, 0.0)),
                   events=(Event("ego_teleport", 0.5, 0.0), Event("sim_error", 0.5, 0.0, "boom")))
    assert replay(log, LB1_RULES) == ("sim_error", 0.5)
    after = make_log(xy, ((0.0, 0.0), (100.0, 0.0)), events=(Event("ego_teleport", 0.6, 0.0),))
    assert replay(after, LB1_RULES) == ("stuck", 0.6)  # after the last step (t = 0.45): the event's time


def test_monitor_is_final_and_time_must_increase():
    mon = TerminationMonitor(DenseRoute.from_polyline([(0.0, 0.0), (10.0, 0.0)]), 0.0, LB1_RULES)
    mon.locate(0.0, 40.0)
    assert mon.update(0.0, 5.0) == "route_deviation"
    assert mon.update(1.0, 5.0) == "route_deviation"
    fresh = TerminationMonitor(DenseRoute.from_polyline([(0.0, 0.0), (10.0, 0.0)]), 0.0, LB1_RULES)
    fresh.update(1.0, 5.0)
    with pytest.raises(ValueError, match="backwards"):
        fresh.update(0.5, 5.0)


def test_lb2_route_timeout_grows_with_the_route_advance():
    # 2.0: 300 s, plus each metre of advance at 10 % of the speed limit (10 m/s -> 1 s per m);
    # 50 points passed -> 350 s; 1.0's budget for 100 m is int(85) s
    mon = TerminationMonitor(DenseRoute.from_polyline(ROUTE), 0.0, LB2_RULES)
    for i, (x, y) in enumerate(straight(101)):
        mon.locate(x, y)
        mon.update(0.05 * i, 10.0, 0, (), 10.0, 10.0)
    assert mon.timeout == pytest.approx(350.0)


def test_rescoring_under_rules_that_end_sooner_is_exact_and_later_is_flagged():
    # recorded until 2.0's blocked rule (moving to step 100, then standing): 1.0's route
    # timeout (85 s for 100 m) ends it sooner, at 85.05 s: the cut log is 1.0's run
    n = 3702
    xy = straight(101) + [(50.25, 0.0)] * (n - 101)
    log = lb2_log(xy, speed=[10.0] * 101 + [0.0] * (n - 101), termination="agent_blocked")
    cut, exact = ended_by(log, LB1_RULES)
    assert exact and cut.termination == "route_timeout" and cut.t[-1] == 85.05
    assert score_episode(log, "lb1").termination == "route_timeout"
    assert LB1.ended_by(log) == (cut, True)
    # the other way: 2.0's rules would have run past 85 s, so the cut log is not their run
    short, exact = ended_by(cut, LB2_RULES)
    assert not exact and short is cut
