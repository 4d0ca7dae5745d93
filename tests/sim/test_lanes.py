"""OutsideRouteLanesTest's lane facts (icrsumo.sim.lanes) on the bundled networks, without SUMO."""

from __future__ import annotations

import math

import numpy as np
import pytest

from icrsumo.core.resources import bundled_towns
from icrsumo.sim.lanes import (
    ALLOWED_OUT_DISTANCE,
    DrivingLanes,
    LanePoint,
    WrongLaneState,
    driving_lanes,
    wrong_lane_step,
)
from icrsumo.world.networks import load_net


@pytest.fixture(scope="module", params=["icr_grid", "Town03"])
def town(request):
    net = load_net(bundled_towns()[request.param])
    return net, driving_lanes(net)


def _brute(net, x: float, y: float) -> float:
    best = math.inf
    for shape in net.lane_shape.values():
        for (ax, ay), (bx, by) in zip(shape[:-1], shape[1:]):
            dx, dy = bx - ax, by - ay
            t = min(max(((x - ax) * dx + (y - ay) * dy) / max(dx * dx + dy * dy, 1e-12), 0.0), 1.0)
            best = min(best, math.hypot(ax + dx * t - x, ay + dy * t - y))
    return best


def test_the_grid_finds_the_nearest_lane_of_the_whole_network(town):
    net, lanes = town
    rng = np.random.default_rng(11)
    pts = np.concatenate(list(net.lane_shape.values()))
    lo, hi = pts.min(axis=0) - 30.0, pts.max(axis=0) + 30.0
    for x, y in rng.uniform(lo, hi, (60, 2)):
        p = lanes.nearest(float(x), float(y))
        assert p.dist == pytest.approx(_brute(net, float(x), float(y)), abs=1e-9)
        assert p.junction == p.lane.startswith(":") and p.width > 0


def test_off_lanes_beyond_half_a_width_and_1_3_m(town):
    net, lanes = town
    # an edge's rightmost car lane, long enough; to its right there is no other driving lane
    lane = next(f"{e}_{min(idx)}" for e, idx in sorted(net.passenger_lanes.items())
                if net.edge_length[e] > 40)
    x, y, h = net.lane_pose(lane, 0.5 * net.lane_length[lane])
    on = lanes.nearest(x, y)
    assert on.dist == pytest.approx(0.0, abs=1e-6) and not lanes.off_lanes(on)
    rx, ry = math.sin(h), -math.cos(h)  # right of the heading
    limit = on.width / 2 + ALLOWED_OUT_DISTANCE
    inside = lanes.nearest(x + rx * (limit - 0.2), y + ry * (limit - 0.2))
    assert inside.lane == lane and not lanes.off_lanes(inside)
    # 30 m to the right: off every lane unless another road is there (checked by brute force)
    far_x, far_y = x + rx * 30.0, y + ry * 30.0
    far = lanes.nearest(far_x, far_y)
    assert lanes.off_lanes(far) == (_brute(net, far_x, far_y) > far.width / 2 + ALLOWED_OUT_DISTANCE)


def _pt(lane: str, heading_deg: float, junction: bool = False) -> LanePoint:
    return LanePoint(lane, 0.0, math.radians(heading_deg), 3.2, junction)


def test_wrong_lane_rules():
    s = WrongLaneState()
    s = wrong_lane_step(s, _pt("a_0", 0.0), 0.0)
    assert not s.wrong                                        # the start: nothing to compare
    s = wrong_lane_step(s, _pt("a_1", 5.0), 0.0)
    assert not s.wrong                                        # a lane of the same direction
    s = wrong_lane_step(s, _pt("-a_0", 180.0), 0.0)
    assert s.wrong                                            # across the centre line
    s = wrong_lane_step(s, _pt("-a_0", 180.0), 0.0)
    assert s.wrong                                            # same lane: kept
    s = wrong_lane_step(s, _pt("a_1", 0.0), 0.0)
    assert not s.wrong                                        # back across: flipped again
    s = wrong_lane_step(s, _pt("-a_0", 149.0), 0.0)
    assert not s.wrong                                        # under 150 degrees: a plain change
    s = wrong_lane_step(s, _pt(":j_0_0", 90.0, junction=True), 0.0)
    assert not s.wrong                                        # never inside a junction
    s = wrong_lane_step(s, _pt("b_0", 0.0), math.radians(180.0))
    assert s.wrong                                            # out of the junction against the lane
    s = wrong_lane_step(s, _pt(":j_1_0", 0.0, junction=True), 0.0)
    s = wrong_lane_step(s, _pt("c_0", 0.0), math.radians(119.0))
    assert not s.wrong                                        # under 120 degrees off the lane


def test_crossing_into_the_opposite_lane_of_a_real_road():
    net = load_net(bundled_towns()["icr_grid"])
    lanes = DrivingLanes(net)
    sn = net.sumolib_net

    def ends(e: str) -> tuple[str, str]:
        edge = sn.getEdge(e)
        return edge.getFromNode().getID(), edge.getToNode().getID()

    by_ends = {ends(e): e for e in sorted(net.passenger_lanes)}
    edge = next(e for e in sorted(net.passenger_lanes) if ends(e)[::-1] in by_ends)  # a two-way road
    lane = f"{edge}_{max(net.passenger_lanes[edge])}"  # the lane next to the centre line
    x, y, h = net.lane_pose(lane, 0.5 * net.lane_length[lane])
    lx, ly = -math.sin(h), math.cos(h)  # left of the heading: towards the opposite lanes
    s, seen = WrongLaneState(), []
    for d in np.arange(0.0, 6.01, 0.25):
        p = lanes.nearest(x + lx * d, y + ly * d)
        s = wrong_lane_step(s, p, h)
        seen.append(s.wrong)
    assert not seen[0] and seen[-1]  # in the opposite direction's lane once across
