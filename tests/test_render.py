"""BEV rasterisation (icrsumo.render) on the bundled networks: frame convention, layers, video."""

from __future__ import annotations

import math
import time

import cv2
import numpy as np
import pytest

from icrsumo.core import resources
from icrsumo.render import CHANNELS, BevRenderer, BevSpec, VideoWriter, to_rgb
from icrsumo.world.networks import load_net

SPEC = BevSpec()
ROW0, COL0 = int(SPEC.ego_row), int(SPEC.ego_col)  # 96, 64
PX = 1.0 / SPEC.m_per_px                           # px per m
CH = {name: i for i, name in enumerate(CHANNELS)}
EGO_SIZE = (4.5, 1.9)
NO_VEH = np.zeros((0, 5))
NO_PED = np.zeros((0, 2))


@pytest.fixture(scope="module")
def grid():
    net = load_net(resources.bundled_towns()["icr_grid"])
    return net, BevRenderer(net)


def _straight_lane(net, min_len: float = 90.0) -> str:
    """A straight normal passenger lane (2-point shape) of at least ``min_len`` m."""
    for lid in sorted(net.lane_shape):
        if not lid.startswith(":") and len(net.lane_shape[lid]) == 2 and net.lane_length[lid] >= min_len:
            return lid
    raise AssertionError("no straight lane")


def _offset(pose, forward: float, left: float = 0.0) -> tuple[float, float]:
    x, y, h = pose
    return (x + forward * math.cos(h) - left * math.sin(h), y + forward * math.sin(h) + left * math.cos(h))


def _blob_centre(layer: np.ndarray) -> tuple[float, float]:
    rows, cols = np.nonzero(layer)
    assert len(rows), "empty layer"
    return float(rows.mean()), float(cols.mean())


def _mid_pose(net, lid):
    return net.lane_pose(lid, net.lane_length[lid] / 2)


def test_shape_dtype_channels_and_determinism(grid):
    net, r = grid
    pose = _mid_pose(net, _straight_lane(net))
    veh = np.array([[*_offset(pose, 10), pose[2] + 0.3, 4.5, 1.9]])
    ped = np.array([_offset(pose, 5, 4)])
    states = {t: "rGy" * 10 for t in r.tls_ids}
    a = r.render(pose, EGO_SIZE, veh, ped, states)
    assert a.shape == (len(CHANNELS), SPEC.height, SPEC.width) == (7, 128, 128)
    assert a.dtype == np.uint8
    assert set(np.unique(a).tolist()) <= {0, 255}
    assert CHANNELS == ("drivable", "markings", "vehicles", "pedestrians", "ego", "stop", "go")
    b = r.render(pose, EGO_SIZE, veh.copy(), ped.copy(), dict(states))
    c = BevRenderer(net).render(pose, EGO_SIZE, veh, ped, states)
    assert a.tobytes() == b.tobytes() == c.tobytes()
    assert a is not b  # a fresh array every call


def test_ego_drawn_only_at_its_place_and_on_drivable(grid):
    net, r = grid
    pose = _mid_pose(net, _straight_lane(net))
    out = r.render(pose, EGO_SIZE, NO_VEH, NO_PED, {})
    ego = out[CH["ego"]]
    assert ego[ROW0, COL0] == 255
    rows, cols = np.nonzero(ego)
    assert np.abs(rows - ROW0).max() <= EGO_SIZE[0] / 2 * PX + 1
    assert np.abs(cols - COL0).max() <= EGO_SIZE[1] / 2 * PX + 1
    assert abs(len(rows) - EGO_SIZE[0] * EGO_SIZE[1] * PX * PX) < 16
    assert out[CH["drivable"]][ROW0, COL0] == 255
    assert not out[CH["vehicles"]].any() and not out[CH["pedestrians"]].any()


def test_nothing_static_far_from_roads(grid):
    net, r = grid
    xmin = min(s[:, 0].min() for s in net.lane_shape.values())
    out = r.render((xmin - 500.0, 0.0, 0.3), EGO_SIZE, NO_VEH, NO_PED, {t: "r" * 20 for t in r.tls_ids})
    for name in ("drivable", "markings", "stop", "go", "vehicles", "pedestrians"):
        assert not out[CH[name]].any(), name
    assert out[CH["ego"]].any()


def test_vehicle_ahead_and_left(grid):
    net, r = grid
    pose = _mid_pose(net, _straight_lane(net))
    ahead = np.array([[*_offset(pose, 10.0), pose[2], 4.5, 1.9]])
    row, col = _blob_centre(r.render(pose, EGO_SIZE, ahead, NO_PED, {})[CH["vehicles"]])
    assert abs(row - (ROW0 - 10 * PX)) <= 1.0 and abs(col - COL0) <= 1.0
    left = np.array([[*_offset(pose, 0.0, 10.0), pose[2], 4.5, 1.9]])
    layer = r.render(pose, EGO_SIZE, left, NO_PED, {})[CH["vehicles"]]
    row, col = _blob_centre(layer)
    assert abs(row - ROW0) <= 1.0 and abs(col - (COL0 - 10 * PX)) <= 1.0
    rows, cols = np.nonzero(layer)  # same heading as the ego: long side vertical
    assert np.ptp(rows) > np.ptp(cols)
    # a crossing vehicle (heading +90 deg relative) is long horizontally
    cross = np.array([[*_offset(pose, 10.0), pose[2] + math.pi / 2, 4.5, 1.9]])
    rows, cols = np.nonzero(r.render(pose, EGO_SIZE, cross, NO_PED, {})[CH["vehicles"]])
    assert np.ptp(cols) > np.ptp(rows)
    # far vehicles are filtered out; empty/None inputs are fine
    far = np.array([[*_offset(pose, 200.0), pose[2], 4.5, 1.9]])
    assert not r.render(pose, EGO_SIZE, far, None, {})[CH["vehicles"]].any()


def test_rotating_the_ego_rotates_the_map(grid):
    net, r = grid
    lid = _straight_lane(net)
    pose = _mid_pose(net, lid)
    # 20 m ahead along the lane is drivable, 20 m to the left is not (grid blocks are large)
    assert net.project(*_offset(pose, 20.0), 1.0)
    assert not net.project(*_offset(pose, 0.0, 20.0), 6.0)
    d = 20 * int(PX)
    out = r.render(pose, EGO_SIZE, NO_VEH, NO_PED, {})[CH["drivable"]]
    assert out[ROW0 - d, COL0] == 255 and out[ROW0, COL0 - d] == 0
    # turned 90 deg to the left: the old "ahead" is now on the right, the old "left" ahead
    x, y, h = pose
    out = r.render((x, y, h + math.pi / 2), EGO_SIZE, NO_VEH, NO_PED, {})[CH["drivable"]]
    assert out[ROW0, COL0 + d] == 255 and out[ROW0 - d, COL0] == 0
    # the raster of the rotated ego equals the original one rotated by 90 deg clockwise
    # (only compared on the square centred on the ego, both render windows covering it)
    a = r.render(pose, EGO_SIZE, NO_VEH, NO_PED, {})[CH["drivable"]]
    b = r.render((x, y, h + math.pi / 2), EGO_SIZE, NO_VEH, NO_PED, {})[CH["drivable"]]
    k = 30
    wa = a[ROW0 - k:ROW0 + k + 1, COL0 - k:COL0 + k + 1]
    wb = b[ROW0 - k:ROW0 + k + 1, COL0 - k:COL0 + k + 1]
    assert (np.rot90(wa, k=-1) != wb).mean() < 0.02


def test_a_standing_ego_reuses_the_static_layers_exactly(grid):
    """The static layers of an unchanged pose come from the render before (no warp): every frame
    equals a fresh renderer's, whatever the lights and traffic drew on the frame before."""
    net, _ = grid
    r = BevRenderer(net)
    tid, _lid, pose = _tl_approach(net, r, 20.0)
    n = 1 + max(link for t, link, _ in r.tl_segments if t == tid)
    veh = np.array([[*_offset(pose, 10), pose[2], 4.5, 1.9]])
    moved = (*_offset(pose, 1.0), pose[2])
    calls = [(pose, veh, {tid: "r" * n}), (pose, NO_VEH, {}), (pose, veh, {tid: "G" * n}),
             (moved, NO_VEH, {}), (pose, NO_VEH, {tid: "r" * n}), ((*pose[:2], pose[2] + 1e-9), NO_VEH, {})]
    frames = [r.render(p, EGO_SIZE, v, NO_PED, st) for p, v, st in calls]
    for (p, v, st), got in zip(calls, frames):
        assert got.tobytes() == BevRenderer(net).render(p, EGO_SIZE, v, NO_PED, st).tobytes()
    assert frames[3].tobytes() != frames[1].tobytes()


def _tl_approach(net, r, before: float = 20.0):
    """An incoming car lane of a traffic light in icr_grid and the ego pose ``before`` m ahead of
    its end."""
    sn = net.sumolib_net
    for tid, _link, _seg in r.tl_segments:
        for entries in sn.getTLS(tid).getLinks().values():
            lane = entries[0][0]
            lid = lane.getID()
            if lid in net.lane_shape and net.lane_length[lid] > before + 10 and len(net.lane_shape[lid]) == 2:
                return tid, lid, net.lane_pose(lid, net.lane_length[lid] - before)
    raise AssertionError("no traffic-light approach")


def test_traffic_light_stop_and_go(grid):
    net, r = grid
    tid, lid, pose = _tl_approach(net, r, 20.0)
    assert net.node_type[net.sumolib_net.getLane(lid).getEdge().getToNode().getID()] == "traffic_light"
    n = 1 + max(link for t, link, _ in r.tl_segments if t == tid)
    d = 20 * int(PX)

    def at_line(layer):  # the ego lane's stop line: about 20 m ahead, across the ego's column
        return layer[ROW0 - d - 3:ROW0 - d + 4, COL0 - 3:COL0 + 4].any()

    red = r.render(pose, EGO_SIZE, NO_VEH, NO_PED, {tid: "r" * n})
    assert at_line(red[CH["stop"]]) and not red[CH["go"]].any()
    green = r.render(pose, EGO_SIZE, NO_VEH, NO_PED, {tid: "G" * n})
    assert at_line(green[CH["go"]]) and not green[CH["stop"]].any()
    for ch, expect in (("y", "stop"), ("s", "stop"), ("g", "go")):
        out = r.render(pose, EGO_SIZE, NO_VEH, NO_PED, {tid: ch * n})
        assert at_line(out[CH[expect]]), ch
    for ch in "oOu":
        out = r.render(pose, EGO_SIZE, NO_VEH, NO_PED, {tid: ch * n})
        assert not out[CH["stop"]].any() and not out[CH["go"]].any(), ch
    # a light missing from tl_states, or a too short state string, draws nothing
    assert not r.render(pose, EGO_SIZE, NO_VEH, NO_PED, {})[[CH["stop"], CH["go"]]].any()
    assert not r.render(pose, EGO_SIZE, NO_VEH, NO_PED, {tid: ""})[[CH["stop"], CH["go"]]].any()
    # a per-link state splits the ego lane's line: its own links decide what is drawn there
    links = sorted(link for t, link, seg in r.tl_segments if t == tid)
    mine = {link for t, link, seg in r.tl_segments
            if t == tid and np.hypot(*(seg.mean(axis=0) - net.lane_shape[lid][-1])).min() < 2.5}
    assert mine and set(links) > mine
    state = "".join("G" if i in mine else "r" for i in range(n))
    out = r.render(pose, EGO_SIZE, NO_VEH, NO_PED, {tid: state})
    assert at_line(out[CH["go"]]) and not at_line(out[CH["stop"]])
    assert out[CH["stop"]].any()  # the other approaches are red


def test_stop_sign_lines_in_tjunctions():
    net = load_net(resources.bundled_towns()["icr_tjunctions"])
    r = BevRenderer(net)
    sn = net.sumolib_net
    lid = next(
        lid for lid in sorted(net.lane_shape)
        if not lid.startswith(":")
        and sn.getLane(lid).getEdge().getToNode().getType() == "priority_stop"
        and any(c.getState() == "s" for c in sn.getLane(lid).getOutgoing())
        and net.lane_length[lid] > 25 and len(net.lane_shape[lid]) == 2
    )
    pose = net.lane_pose(lid, net.lane_length[lid] - 15.0)
    out = r.render(pose, EGO_SIZE, NO_VEH, NO_PED, {})
    d = 15 * int(PX)
    assert out[CH["stop"]][ROW0 - d - 3:ROW0 - d + 4, COL0 - 3:COL0 + 4].any()
    assert not out[CH["go"]].any()
    # the stop line spans the lane width (3.2 m = 6.4 px), perpendicular to the lane
    rows, cols = np.nonzero(out[CH["stop"]][ROW0 - d - 4:ROW0 - d + 5, COL0 - 8:COL0 + 9])
    assert 5 <= np.ptp(cols) + 1 <= 9 and np.ptp(rows) + 1 <= 3


def test_pedestrians_drawn(grid):
    net, r = grid
    pose = _mid_pose(net, _straight_lane(net))
    ped = np.array([_offset(pose, 5.0, 3.0), _offset(pose, 300.0)])
    layer = r.render(pose, EGO_SIZE, NO_VEH, ped, {})[CH["pedestrians"]]
    row, col = _blob_centre(layer)
    assert abs(row - (ROW0 - 5 * PX)) <= 1.0 and abs(col - (COL0 - 3 * PX)) <= 1.0
    assert 4 <= np.count_nonzero(layer) <= 9


def test_markings_on_two_lane_edge():
    net = load_net(resources.bundled_towns()["icr_arterial"])
    r = BevRenderer(net)
    right = next(f"{e}_{idx[0]}" for e, idx in sorted(net.passenger_lanes.items()) if len(idx) == 2
                 and len(net.lane_shape[f"{e}_{idx[0]}"]) == 2 and net.lane_length[f"{e}_{idx[0]}"] > 80)
    pose = _mid_pose(net, right)  # the right car lane (a sidewalk on its right, a car lane on its left)
    out = r.render(pose, EGO_SIZE, NO_VEH, NO_PED, {})
    mk = out[CH["markings"]]
    half = 1.6 * PX  # half lane width in px
    rows = range(ROW0 - 30, ROW0 + 30)
    between = int(round(COL0 - half))      # boundary between lane 0 and lane 1
    road_edge = int(round(COL0 + half))    # right road edge
    for c in (between, road_edge):
        assert np.mean([mk[row, c - 1:c + 2].any() for row in rows]) > 0.95, c
    assert not mk[ROW0, COL0 - 2:COL0 + 3].any()  # no marking down the middle of the ego lane
    assert out[CH["drivable"]][ROW0, int(COL0 - 2 * half)] == 255  # the left lane is drivable
    assert out[CH["drivable"]][ROW0, int(COL0 + half + 2)] == 0  # the sidewalk is not


def test_to_rgb_colours(grid):
    net, r = grid
    pose = _mid_pose(net, _straight_lane(net))
    raster = r.render(pose, EGO_SIZE, NO_VEH, NO_PED, {})
    img = to_rgb(raster)
    assert img.shape == (128, 128, 3) and img.dtype == np.uint8
    g = img[ROW0, COL0]
    assert g[1] > g[0] and g[1] > g[2]  # green ego
    road = img[ROW0 - 20, COL0]
    assert road[0] == road[1] == road[2] > 40  # grey road
    with pytest.raises(ValueError):
        to_rgb(raster[:3])


def test_bevspec_validation():
    with pytest.raises(ValueError):
        BevSpec(m_per_px=0.0)
    with pytest.raises(ValueError):
        BevSpec(behind_m=100.0)
    assert BevSpec().ahead_m == 48.0 and BevSpec().ego_row == 96.0


def test_custom_spec(grid):
    net, _ = grid
    spec = BevSpec(m_per_px=0.25, height=96, width=64, behind_m=8.0)
    r = BevRenderer(net, spec)
    pose = _mid_pose(net, _straight_lane(net))
    veh = np.array([[*_offset(pose, 5.0), pose[2], 4.5, 1.9]])
    out = r.render(pose, EGO_SIZE, veh, NO_PED, {})
    assert out.shape == (7, 96, 64)
    row, col = _blob_centre(out[CH["vehicles"]])
    assert abs(row - (spec.ego_row - 20)) <= 1.0 and abs(col - 32) <= 1.0


def test_video_writer(grid, tmp_path):
    net, r = grid
    lid = _straight_lane(net)
    with VideoWriter(tmp_path / "episode.webm", fps=10, scale=2) as vw:
        for i in range(5):
            pose = net.lane_pose(lid, 10.0 + 2 * i)
            vw.add(r.render(pose, EGO_SIZE, NO_VEH, NO_PED, {}),
                   "Turn left at the next intersection — in 30 meters, then keep going straight on.",
                   notice="Pedestrian ahead" if i == 2 else "", speed=5.0 + i)
    assert vw.frames == 5
    assert vw.path == tmp_path / "episode.webm"  # VP8 in WebM: browsers play it
    head = vw.path.read_bytes()[:4096]
    assert head.startswith(b"\x1a\x45\xdf\xa3") and b"webm" in head and b"V_VP8" in head
    cap = cv2.VideoCapture(str(vw.path))
    try:
        if cap.isOpened():
            n = 0
            while cap.read()[0]:
                n += 1
            assert n == 5
    finally:
        cap.release()
    with pytest.raises(RuntimeError):
        vw.add(np.zeros((7, 128, 128), np.uint8), "late")


def _timed_frames(town: str, frames: int = 500) -> float:
    net = load_net(resources.bundled_towns()[town])
    r = BevRenderer(net)
    rng = np.random.default_rng(0)
    lanes = sorted(lid for lid in net.lane_shape if not lid.startswith(":"))
    states = {t: "GgrRyys" * 8 for t in r.tls_ids}
    times = []
    for i in range(frames):
        lid = lanes[i % len(lanes)]
        pose = _mid_pose(net, lid)
        fwd, lft = rng.uniform(-14, 46, 40), rng.uniform(-30, 30, 40)
        pts = np.array([_offset(pose, f, left) for f, left in zip(fwd, lft)])
        veh = np.column_stack([pts[:30], rng.uniform(-np.pi, np.pi, 30), np.full(30, 4.5), np.full(30, 1.9)])
        t0 = time.perf_counter()
        r.render(pose, EGO_SIZE, veh, pts[30:], states)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


@pytest.mark.parametrize("town", ["icr_grid", "icr_highway"])
def test_render_time_report(town):
    """Measured, not asserted: median per-frame time with 30 vehicles and 10 pedestrians in view."""
    med = _timed_frames(town)
    print(f"\nBEV render {town}: median {med * 1e3:.3f} ms/frame (128x128, 30 vehicles, 10 pedestrians)")
    assert med > 0
