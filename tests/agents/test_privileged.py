"""The privileged agents' junction foes (pure geometry) and, in SUMO, the LangAuto routes whose
route-oracle infractions were root-caused (README, *Fidelity on CARLA's towns*)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from icrsumo.agents.conflicts import ConflictMap, junction_of, project
from icrsumo.core.resources import bundled_towns
from icrsumo.world.networks import load_net


def test_project_on_segments_not_vertices():
    # one 32 m segment: a car standing on it 16 m along is on the path (FINDINGS: route 6)
    pts = np.array([[0.0, 0.0], [32.0, 0.0]])
    cum = np.array([0.0, 32.0])
    xy = np.array([[16.0, 0.5], [16.0, 3.0], [-5.0, 0.0], [40.0, 0.0]])
    s = project(pts, cum, xy, corridor=1.5)
    assert s[0] == pytest.approx(16.0)
    assert math.isnan(s[1])                      # 3 m off the line
    assert math.isnan(s[2]) and math.isnan(s[3])  # beyond the ends, 5 and 8 m away
    assert project(pts, cum, np.array([[-1.0, 0.0]]))[0] == pytest.approx(0.0)  # clamped to the start
    # heading: a car crossing the path at right angles is not on it when yaws are given
    s = project(pts, cum, xy[:1], yaw=np.array([math.pi / 2]))
    assert math.isnan(s[0])
    s = project(pts, cum, xy[:1], yaw=np.array([0.2]))
    assert s[0] == pytest.approx(16.0)


def test_project_empty_inputs():
    assert project(np.zeros((1, 2)), np.zeros(1), np.array([[1.0, 1.0]])).shape == (1,)
    assert project(np.array([[0.0, 0.0], [1.0, 0.0]]), np.array([0.0, 1.0]), np.zeros((0, 2))).shape == (0,)


def _meets_first_at(net, conn, conflict):
    """A merge's conflict point is where the two lanes first come within MERGE_M of each
    other (two cars side by side), not their common end."""
    import numpy as np
    from shapely.geometry import LineString

    from icrsumo.agents.conflicts import MERGE_M, MERGE_STEP

    ours = LineString(np.concatenate([net.lane_shape[v] for v in conn.via_chain]))
    theirs = LineString(np.concatenate([net.lane_shape[v] for v in conflict.foe.via_chain]))
    s = conflict.s_ours
    if s < ours.length:
        assert ours.interpolate(s).distance(theirs) < MERGE_M
    if s >= MERGE_STEP:
        assert ours.interpolate(s - MERGE_STEP).distance(theirs) >= MERGE_M


def test_left_turn_conflicts_with_oncoming_straight():
    """LangAuto-long route 73 (Town07, tls 725): the ego's permissive left turn crosses the
    oncoming straight (27 -> 26#1) and merges with the oncoming right turn (27 -> -15)."""
    net = load_net(bundled_towns()["Town07"])
    left = net.connections[("-26#1", "-15")][0]
    assert left.direction == "l" and junction_of(left.via) == "725"
    conflicts = {(c.foe.from_edge, c.foe.to_edge): c for c in ConflictMap(net)(left)}
    straight = conflicts[("27", "26#1")]
    assert not straight.merge and 0.0 < straight.s_ours < left.via_length
    # the conflict point lies on the foe's internal lane, after its approach tail
    assert straight.entry < straight.s_foe <= straight.cum[-1] + 1e-6
    right = conflicts[("27", "-15")]
    assert right.merge and 0.0 < right.s_ours < left.via_length - 1.0
    _meets_first_at(net, left, right)
    # connections from the ego's own incoming edge are never foes
    assert all(c.foe.from_edge != "-26#1" for c in conflicts.values())


def test_ramp_merges_with_the_highway():
    """LangAuto-long route 37 (Town04, junction 1082): the on-ramp 34 -> -39 ends on the lane
    the highway's rightmost lane -38 -> -39 ends on: a merge, at the end of both."""
    net = load_net(bundled_towns()["Town04"])
    ramp = net.connections[("34", "-39")][0]
    assert ramp.state == "m"
    merges = [c for c in ConflictMap(net)(ramp) if c.merge]
    assert [(c.foe.from_edge, c.foe.from_lane) for c in merges] == [("-38", 1)]
    assert 0.0 < merges[0].s_ours <= ramp.via_length + 0.5
    _meets_first_at(net, ramp, merges[0])


def test_conflict_map_caches_per_connection():
    net = load_net(bundled_towns()["Town07"])
    cmap = ConflictMap(net)
    left = net.connections[("-26#1", "-15")][0]
    assert cmap(left) is cmap(left)


#: LangAuto routes whose route-oracle infractions were root-caused and fixed, with the cause
FIXED = {
    ("langauto-long", "28"): "lane change restarted at every replan, red light run at its end",
    ("langauto-long", "37"): "highway merge without yielding to the main road",
    ("langauto-long", "43"): "two lane changes in 28 m never completed, off the road",
    ("langauto-long", "73"): "permissive left turn across an oncoming car",
    ("langauto-long", "89"): "no stop point while waiting for a lane-change gap",
    ("langauto-short", "27"): "junction crossing with a car inside the junction",
    ("langauto-tiny", "57"): "junction crossing with a car inside the junction",
}


@pytest.mark.sumo
@pytest.mark.parametrize(("suite", "route"), sorted(FIXED), ids=lambda v: str(v))
def test_route_oracle_drives_the_root_caused_routes_cleanly(suite, route, cache):
    from icrsumo.agents.privileged import RouteOracle
    from icrsumo.evaluation.bundled import bundled_route
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.scoring import score_episode
    from icrsumo.sim.episode import run_episode
    from icrsumo.world.scenario import read_scenario

    sc_dir, instr = bundled_route(route, suite)
    log = run_episode(read_scenario(sc_dir), read_instruction_sets(instr)[0], RouteOracle())
    result = score_episode(log)
    assert (result.rc, [e.kind for e in log.events if e.kind != "teleport_background"]) == (100.0, []), \
        FIXED[(suite, route)]
