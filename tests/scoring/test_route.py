"""The dense route (icrsumo.scoring.route) the leaderboard's criteria see, no SUMO."""

from __future__ import annotations

import math

import pytest

from icrsumo.scoring.route import DenseRoute


def test_dense_route_is_one_metre_hops_with_the_direction_of_the_route():
    r = DenseRoute.from_polyline([(0.0, 0.0), (2.5, 0.0), (2.5, 2.0)])
    # 4.5 m of arc: points at 0, 1, 2, 3, 4 m and the end; the one at 3 m lies 0.5 m up the 2nd leg
    assert r.x == (0.0, 1.0, 2.0, 2.5, 2.5, 2.5) and r.y == (0.0, 0.0, 0.0, 0.5, 1.5, 2.0)
    assert (r.fx[2], r.fy[2]) == (1.0, 0.0) and (r.fx[3], r.fy[3]) == (0.0, 1.0)
    # accum sums straight lines between points: the corner is cut (2 + hypot(0.5, 0.5) + 1.5)
    assert r.length == pytest.approx(2.0 + math.hypot(0.5, 0.5) + 1.5)



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
