"""The ego's lane search grid (icrsumo.sim.match): narrower only where SUMO picks the same lane."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from icrsumo.sim.match import FULL_RADIUS, RADII, build_match_grid, match_grid
from icrsumo.world.networks import load_net

NETS = Path(__file__).resolve().parents[2] / "networks"


def test_a_lone_lane_needs_sumos_full_search_on_it():
    """One straight lane and nothing beside it: on the lane no lane lies between 3.2 m and a
    narrow radius, so SUMO's distance normaliser could change, and 100 m are searched; 5 m
    beside it the lane itself is such a lane."""
    g = build_match_grid({"a_0": np.array([[0.0, 0.0], [200.0, 0.0]])})
    assert g.radius(100.0, 0.0) == g.radius(100.0, 2.5) == FULL_RADIUS
    assert g.radius(100.0, 5.5) == RADII[1]


def test_a_lane_beside_allows_a_narrow_search_but_not_past_the_lanes_end():
    lanes = {"a_0": np.array([[0.0, 0.0], [200.0, 0.0]]),
             "a_1": np.array([[0.0, 4.0], [200.0, 4.0]])}
    g = build_match_grid(lanes)
    assert g.radius(100.0, -0.3) == RADII[0]         # on a_0, a_1 4.3 m away: (A) and (B) hold
    assert g.radius(100.0, 2.0) == FULL_RADIUS       # both lanes nearer than 3.2 m + the cell
    assert g.radius(-3.0, 0.0) == FULL_RADIUS        # past both lanes' ends: ambiguous mapping
    assert g.radius(100.0, 60.0) == FULL_RADIUS      # off the road
    assert g.radius(1e6, 1e6) == FULL_RADIUS         # off the grid
    # a lane SUMO would score as the moved vehicle's own id ("_-1") disables the grid
    assert build_match_grid({**lanes, "_-1": lanes["a_1"]}).radius(100.0, -0.3) == FULL_RADIUS
    assert build_match_grid(lanes, frozenset({"_-1"})).radius(100.0, -0.3) == FULL_RADIUS


def test_every_bundled_network_has_narrow_cells():
    for name in ("icr_grid.net.xml", "carla/Town03.net.xml"):
        share = match_grid(load_net(NETS / name)).share()
        assert math.isclose(sum(share.values()), 1.0)
        assert share[FULL_RADIUS] < 0.8 and share[RADII[0]] > 0.05


def test_tiles_computed_when_needed_equal_the_whole_grid():
    """The grid is computed tile by tile as the ego comes near; any tile equals the same cells
    computed with the whole network at once."""
    grid = match_grid(load_net(NETS / "carla/Town10HD.net.xml"))
    fresh = build_match_grid(load_net(NETS / "carla/Town10HD.net.xml").lane_shape)
    ny, nx = fresh.extent
    whole = fresh.codes(0, 0, ny, nx)
    radii = np.array([*fresh.radii, FULL_RADIUS])
    assert not fresh._tiles                       # nothing computed before it is asked for
    rng = np.random.default_rng(7)
    for i, j in zip(rng.integers(ny, size=3000), rng.integers(nx, size=3000), strict=True):
        x, y = fresh.x0 + (j + 0.5) * fresh.cell, fresh.y0 + (i + 0.5) * fresh.cell
        assert grid.radius(x, y) == fresh.radius(x, y) == radii[whole[i, j]]


def _moves(net_path: Path, poses: list[tuple[float, float, float]], radius) -> list[tuple]:
    """Move a vehicle to each pose in turn (SUMO's moveToXY, keepRoute=2, search ``radius(x,
    y)`` m), one step each; SUMO's lane, lane position, lateral position and pose after each."""
    import tempfile

    from icrsumo.sim.backend import _libsumo

    ls = _libsumo()
    net = load_net(net_path)
    edge = next(e for e in sorted(net.passenger_lanes) if net.edge_length[e] > 20)
    with tempfile.TemporaryDirectory() as tmp:
        routes = Path(tmp) / "r.rou.xml"
        routes.write_text(f'<routes><vType id="car" vClass="passenger"/>'
                          f'<route id="r" edges="{edge}"/></routes>')
        ls.start(["sumo", "-n", str(net_path), "-r", str(routes), "--no-step-log", "true",
                  "--no-warnings", "true", "--collision.action", "none"])
        try:
            ls.vehicle.add("ego", "r", typeID="car", depart="now")
            ls.simulationStep()
            out = []
            for x, y, yaw in poses:
                ls.vehicle.moveToXY("ego", "", -1, x, y, yaw, 2, radius(x, y))
                ls.simulationStep()
                v = ls.vehicle
                out.append((v.getLaneID("ego"), v.getLanePosition("ego"), v.getLateralLanePosition("ego"),
                            v.getPosition("ego"), v.getAngle("ego"), v.getRoadID("ego")))
            return out
        finally:
            ls.close()


@pytest.mark.sumo
@pytest.mark.parametrize("name", ["carla/Town03.net.xml", "carla/Town10HD.net.xml", "icr_roundabout.net.xml"])
def test_the_grid_picks_sumos_lane(name):
    """Moves to 1,500 poses near the lanes (up to 6 m beside them, headings off by up to 40
    degrees, one in ten reversed): with the grid's radii SUMO ends on the same lane, position
    and pose after every step as with its full 100 m search; most moves used a narrow radius."""
    net_path = NETS / name
    net = load_net(net_path)
    grid = match_grid(net)
    rng = np.random.default_rng(48)
    lanes = sorted(net.lane_shape)
    poses = []
    for _ in range(1500):
        shape = net.lane_shape[lanes[int(rng.integers(len(lanes)))]]
        i = int(rng.integers(len(shape) - 1))
        a, b = shape[i], shape[i + 1]
        t = float(rng.random())
        heading = math.atan2(b[1] - a[1], b[0] - a[0])
        off = float(rng.uniform(-6.0, 6.0))
        x = a[0] + t * (b[0] - a[0]) - off * math.sin(heading)
        y = a[1] + t * (b[1] - a[1]) + off * math.cos(heading)
        yaw = heading + math.radians(float(rng.uniform(-40.0, 40.0)))
        yaw += math.pi if rng.random() < 0.1 else 0.0
        poses.append((float(x), float(y), (90.0 - math.degrees(yaw)) % 360.0))
    narrow = sum(grid.radius(x, y) < FULL_RADIUS for x, y, _ in poses)
    print(name, narrow / len(poses))
    assert narrow > 0.4 * len(poses)
    assert _moves(net_path, poses, grid.radius) == _moves(net_path, poses, lambda x, y: FULL_RADIUS)
