"""Leaderboard 1.0's route criteria (icrsumo.termination) on hand-built logs, no SUMO.

Every log here is a straight or L-shaped route, 20 Hz steps (0.05 s) and an ego centre moving
0.5 m per step from x = 0.25, so step i is at x = 0.25 + 0.5 i and passes the dense route's
point k (at x = k, direction +x) on the first step with x > k. Expected values are worked out
in the comments from the rules in icrsumo/termination.py (RouteCompletionTest, InRouteTest,
OutsideRouteLanesTest, ActorSpeedAboveThresholdTest, the route timeout).
"""

from __future__ import annotations

import math

import pytest

from icrsumo.termination import (
    BLOCKED_S,
    DEVIATION_M,
    DenseRoute,
    TerminationMonitor,
    replay,
    route_timeout,
    run_monitor,
)
from icrsumo.types import EpisodeLog, Event

DT = 0.05


def make_log(xy: list[tuple[float, float]], route: tuple[tuple[float, float], ...], *,
             speed: list[float] | None = None, outside: list[int] | None = None,
             events: tuple[Event, ...] = (), termination: str = "route_timeout") -> EpisodeLog:
    n = len(xy)
    t = tuple(round(DT * i, 3) for i in range(n))
    return EpisodeLog(
        route_id="r", agent="a", family="baseline", k=0, seed=1, step_length=DT,
        route_length=DenseRoute.from_polyline(route).length, t=t,
        x=tuple(p[0] for p in xy), y=tuple(p[1] for p in xy), yaw=(0.0,) * n,
        speed=tuple(speed) if speed is not None else (10.0,) * n, progress=(0.0,) * n,
        instruction=(0,) * n, outside=tuple(outside) if outside is not None else (0,) * n,
        route_dist=(0.0,) * n, events=events, termination=termination, termination_t=t[-1] if n else 0.0,
        route=route,
    )


def straight(n: int, y: float = 0.0) -> list[tuple[float, float]]:
    return [(0.25 + 0.5 * i, y) for i in range(n)]


def test_constants_and_the_truncated_timeout():
    assert DEVIATION_M == 30.0 and BLOCKED_S == 180.0
    assert route_timeout(100.0) == 85.0          # int(0.8 * 100 + 5)
    assert route_timeout(100.6) == 85.0          # int(85.48): truncated to whole seconds
    assert route_timeout(0.0) == 5.0


def test_dense_route_is_one_metre_hops_with_the_direction_of_the_route():
    r = DenseRoute.from_polyline([(0.0, 0.0), (2.5, 0.0), (2.5, 2.0)])
    # 4.5 m of arc: points at 0, 1, 2, 3, 4 m and the end; the one at 3 m lies 0.5 m up the 2nd leg
    assert r.x == (0.0, 1.0, 2.0, 2.5, 2.5, 2.5) and r.y == (0.0, 0.0, 0.0, 0.5, 1.5, 2.0)
    assert (r.fx[2], r.fy[2]) == (1.0, 0.0) and (r.fx[3], r.fy[3]) == (0.0, 1.0)
    # accum sums straight lines between points: the corner is cut (2 + hypot(0.5, 0.5) + 1.5)
    assert r.length == pytest.approx(2.0 + math.hypot(0.5, 0.5) + 1.5)


def test_completion_needs_more_than_99_percent_and_10_m():
    # 100 m route: RC > 99 % needs point 100 passed (x > 100: step 200, x = 100.25, t = 10.0),
    # and the goal (100, 0) is then 0.25 m away; the old rule (99 % or 10 m) ended at x = 90
    log = make_log(straight(220), ((0.0, 0.0), (100.0, 0.0)), termination="completed")
    mon, end = run_monitor(log)
    assert end == ("completed", 10.0)
    assert mon.completion_pct == 100.0


def test_finishing_5_m_short_of_the_end_is_not_completion():
    # stops at x = 95.25 (step 190) and stands: point 95 passed -> RC 95 %; never blocked before
    # the route timeout: int(0.8 * 100 + 5) = 85 s, reached at the first t > 85.0, i.e. 85.05 s
    n = 1702
    xy = straight(191) + [(95.25, 0.0)] * (n - 191)
    speed = [10.0] * 191 + [0.0] * (n - 191)
    mon, end = run_monitor(make_log(xy, ((0.0, 0.0), (100.0, 0.0)), speed=speed))
    assert end == ("route_timeout", 85.05)
    assert mon.completion_pct == pytest.approx(95.0)


def test_blocked_counts_from_the_last_step_at_or_above_0_1_m_s():
    # 300 m route (timeout int(245) = 245 s); moving until step 100 (t = 5.0), then 0.05 m/s:
    # blocked at the first t with t - 5.0 > 180, i.e. 185.05 s
    n = 3702
    xy = straight(101) + [(50.25, 0.0)] * (n - 101)
    speed = [10.0] * 101 + [0.05] * (n - 101)
    _, end = run_monitor(make_log(xy, ((0.0, 0.0), (300.0, 0.0)), speed=speed))
    assert end == ("agent_blocked", 185.05)


def test_a_wrong_turn_into_a_legal_lane_is_a_deviation_at_30_m():
    # along x to (50, 0), then up +y at x = 50; the nearest of the next route points is (50, 0),
    # 30 m or more away once y >= 30 -> route deviation on that step; RC: point 49 passed
    # (x = 50 is not > 50), so 49 of 200 m = 24.5 %
    xy = straight(100) + [(50.0, 0.5 * j) for j in range(1, 70)]
    mon, end = run_monitor(make_log(xy, ((0.0, 0.0), (200.0, 0.0))))
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
    mon, end = run_monitor(make_log(straight(120, y=20.0), ((0.0, 0.0), (100.0, 0.0))))
    assert end == ("route_deviation", 3.05)
    assert mon.completion_pct == pytest.approx(30.0)


def test_within_15_m_the_route_may_be_followed_off_centre():
    # 9 m off the centre line: never deviated, and the goal is 9.003 m away at x = 100.25 (< 10)
    _, end = run_monitor(make_log(straight(220, y=9.0), ((0.0, 0.0), (100.0, 0.0)),
                                  termination="completed"))
    assert end == ("completed", 10.0)
    # 14.9 m off, stopping at x = 100.25: never deviated, but never within 10 m of the goal
    # either: the route times out
    xy = straight(201, y=14.9) + [(100.25, 14.9)] * 1501
    speed = [10.0] * 201 + [0.0] * 1501
    _, end = run_monitor(make_log(xy, ((0.0, 0.0), (100.0, 0.0)), speed=speed))
    assert end == ("route_timeout", 85.05)


def test_a_shortcut_through_a_junction_still_completes():
    # an L-shaped route (0,0) -> (50,0) -> (50,50); the ego cuts the corner on the diagonal from
    # (40, 0) to (50, 10), then goes up x = 50: progress catches up 2 points per step, nothing is
    # charged, and the route completes (100 m) once y > 50
    route = ((0.0, 0.0), (50.0, 0.0), (50.0, 50.0))
    xy = straight(80) + [(40.0 + 0.25 * j, 0.25 * j) for j in range(1, 41)] + \
        [(50.0, 10.0 + 0.5 * j) for j in range(1, 90)]
    mon, end = run_monitor(make_log(xy, route, termination="completed"))
    assert end[0] == "completed" and mon.completion_pct == 100.0 and mon.outside_pct == 0.0


def test_outside_lanes_counts_route_advance_on_flagged_steps():
    # 100 m route, flagged (wrong lane, bit 2) while 20 < x <= 40: the steps that pass points
    # 20..39 (x = k + 0.25) are flagged -> 20 m of 100 m advanced: 20 %
    xy = straight(220)
    flags = [2 if 20 < x <= 40 else 0 for x, _ in xy]
    mon, _ = run_monitor(make_log(xy, ((0.0, 0.0), (100.0, 0.0)), outside=flags, termination="completed"))
    assert (mon.outside_m, mon.driven_m) == (20.0, 100.0)
    assert mon.outside_pct == pytest.approx(20.0)


def test_standing_still_off_the_lanes_costs_nothing():
    # flagged only while standing (no route advance on those steps): 0 %
    xy = straight(41) + [(20.25, 0.0)] * 100 + [(20.25 + 0.5 * j, 0.0) for j in range(1, 170)]
    flags = [0] * 41 + [1] * 100 + [0] * 169
    mon, _ = run_monitor(make_log(xy, ((0.0, 0.0), (100.0, 0.0)), outside=flags))
    assert mon.outside_m == 0.0 and mon.outside_pct == 0.0


def test_ending_events_and_replay():
    xy = straight(10)
    log = make_log(xy, ((0.0, 0.0), (100.0, 0.0)),
                   events=(Event("ego_teleport", 0.5, 0.0), Event("sim_error", 0.5, 0.0, "boom")))
    assert replay(log) == ("sim_error", 0.5)
    after = make_log(xy, ((0.0, 0.0), (100.0, 0.0)), events=(Event("ego_teleport", 0.6, 0.0),))
    assert replay(after) == ("stuck", 0.6)  # after the last step (t = 0.45): the event's time


def test_monitor_is_final_and_time_must_increase():
    mon = TerminationMonitor(DenseRoute.from_polyline([(0.0, 0.0), (10.0, 0.0)]), 0.0)
    mon.locate(0.0, 40.0)
    assert mon.update(0.0, 5.0) == "route_deviation"
    assert mon.update(1.0, 5.0) == "route_deviation"
    fresh = TerminationMonitor(DenseRoute.from_polyline([(0.0, 0.0), (10.0, 0.0)]), 0.0)
    fresh.update(1.0, 5.0)
    with pytest.raises(ValueError, match="backwards"):
        fresh.update(0.5, 5.0)


# ------------------------------------------------------------------ the dense route's lane pieces
def _dense(points):
    r = DenseRoute.from_polyline(points)
    return list(zip(r.x, r.y)), [round(math.degrees(math.atan2(fy, fx))) for fx, fy in zip(r.fx, r.fy)]


def test_a_lane_change_step_is_one_step_with_the_lanes_direction():
    # east on y = 0 to x = 3, then the next lane starts 3.5 m to the left at x = 3 (the polyline
    # steps sideways): one step, every point pointing east (the ego passes them as it drives on)
    pts, dirs = _dense([(0.0, 0.0, 0.0), (3.0, 0.0, 0.0), (3.0, 3.5, 0.0), (6.0, 3.5, 0.0)])
    assert pts == [(0.0, 0.0), (1.0, 0.0), (2.0, 0.0), (3.0, 0.0),
                   (3.0, 3.5), (4.0, 3.5), (5.0, 3.5), (6.0, 3.5)]
    assert set(dirs) == {0}


def test_a_gap_along_the_road_is_driven_straight_on():
    # the next lane starts 10 m further ahead: the gap is sampled (1 m hops), not one 10 m step
    pts, _ = _dense([(0.0, 0.0, 0.0), (2.0, 0.0, 0.0), (12.0, 0.5, 0.0), (14.0, 0.5, 0.0)])
    gaps = [math.dist(a, b) for a, b in zip(pts, pts[1:])]
    assert max(gaps) <= 1.0 + 1e-9


def test_a_turn_without_a_lane_shape_is_cut_from_5_m_before_the_corner():
    # south to (0, 0), then a lane heading east that starts at (10, 2): the straight cut starts
    # 5 m before the corner, at (0, 5), and runs in its own direction
    south = -math.pi / 2
    pts, dirs = _dense([(0.0, 20.0, south), (0.0, 0.0, south), (10.0, 2.0, 0.0), (20.0, 2.0, 0.0)])
    assert (0.0, 5.0) in pts and (0.0, 4.0) not in pts
    k = pts.index((0.0, 5.0))
    assert dirs[k + 1] == round(math.degrees(math.atan2(-3.0, 10.0)))


def test_points_doubling_back_along_the_road_are_dropped():
    # south to (0, 0); the next lane starts 7 m back north at (0, 7) and runs south: its points
    # behind (0, 0) are dropped, so the road is counted once
    south = -math.pi / 2
    poly = [(0.0, 20.0, south), (0.0, 0.0, south), (0.0, 7.0, south), (0.0, -10.0, south)]
    pts, _ = _dense(poly)
    ys = [y for _, y in pts]
    assert ys == sorted(ys, reverse=True)  # monotone: never back north
    assert DenseRoute.from_polyline(poly).length == pytest.approx(30.0)
