"""The pure sensors and the drivable area, without SUMO: recorded frames of real episodes
(tests/data/frames/*.json, written by tools/record_frames.py) replayed through
``Sensors.detect`` give back the logged events and readings float for float, and hand-made
frames exercise each rule."""

from __future__ import annotations

import json
import math
from dataclasses import FrozenInstanceError
from pathlib import Path

import numpy as np
import pytest

from icrsumo.core.resources import bundled_towns
from icrsumo.core.vocab import EventKind
from icrsumo.scoring.criteria import OFF_LANES
from icrsumo.sim.drivable import DrivableArea, drivable_area
from icrsumo.sim.frame import Contact, SimFrame, frame_from_dict, frame_to_dict
from icrsumo.sim.lanes import driving_lanes
from icrsumo.sim.sensors import Sensors, SensorState
from icrsumo.world.dynamics import EgoState
from icrsumo.world.networks import load_net

FRAMES = Path(__file__).resolve().parents[1] / "data" / "frames"
CASES = sorted(p.stem for p in FRAMES.glob("*.json"))


def _case(name: str) -> tuple[dict, Sensors]:
    doc = json.loads((FRAMES / f"{name}.json").read_text(encoding="utf-8"))
    net = load_net(bundled_towns()[doc["town"]])
    sensors = Sensors(net, driving_lanes(net), drivable_area(net), tuple(doc["size"]))
    return doc, sensors


def test_every_rule_is_covered_by_a_recording():
    kinds = set()
    for name in CASES:
        doc = json.loads((FRAMES / f"{name}.json").read_text(encoding="utf-8"))
        kinds |= {e[0] for row in doc["steps"] for e in row["events"]}
    assert {"collision_static", "wrong_way", "red_light", "stop_sign", "collision_vehicle"} <= kinds


@pytest.mark.parametrize("name", CASES)
def test_recorded_frames_replay_to_the_logged_events_and_readings(name):
    doc, sensors = _case(name)
    state = SensorState()
    for i, row in enumerate(doc["steps"]):
        frame = frame_from_dict(row["frame"])
        assert frame_to_dict(frame) == row["frame"]
        ego = EgoState(*row["ego"])
        progress, _, outside, _ = row["step"]
        events, state = sensors.detect(state, frame, ego, progress)
        got = [[str(e.kind), e.t, e.pos, e.other, e.x, e.y] for e in events]
        assert got == row["events"], (name, i)
        assert state.outside == outside, (name, i)


def test_detect_is_pure_and_state_is_frozen():
    doc, sensors = _case("blind_tiny_001")
    rows = doc["steps"]
    k = next(i for i, r in enumerate(rows) if r["events"])
    state = SensorState()
    for r in rows[:k]:
        _, state = sensors.detect(state, frame_from_dict(r["frame"]), EgoState(*r["ego"]), r["step"][0])
    frame, ego = frame_from_dict(rows[k]["frame"]), EgoState(*rows[k]["ego"])
    a = sensors.detect(state, frame, ego, rows[k]["step"][0])
    b = sensors.detect(state, frame, ego, rows[k]["step"][0])
    assert a == b and a[0]  # same inputs, same events and state; the input state is untouched
    with pytest.raises(FrozenInstanceError):
        state.outside = 1  # type: ignore[misc]


def _lane_point(net, lane: str, frac: float = 0.5) -> tuple[float, float, float]:
    return net.lane_pose(lane, frac * net.lane_length[lane])


@pytest.fixture(scope="module")
def grid():
    net = load_net(bundled_towns()["icr_grid"])
    lane = next(lid for lid in sorted(net.lane_shape)
                if not lid.startswith(":") and net.lane_length[lid] > 40)
    edge = lane.rsplit("_", 1)[0]
    poly = net.lane_shape[lane]
    del edge, poly
    sensors = Sensors(net, driving_lanes(net), drivable_area(net), (4.6, 1.9))
    return net, lane, sensors


def test_contacts_are_events_on_every_step_of_contact_and_pedestrians_by_kind(grid):
    net, lane, sensors = grid
    x, y, yaw = _lane_point(net, lane)
    ego = EgoState(x, y, yaw, 5.0)
    state = SensorState()
    car, ped = Contact("car1", False), Contact("p0", True)
    # (the ego's contacts, SUMO reported some collision): one event per actor in contact on each
    # step (the leaderboard's CollisionTest, in icrsumo.scoring, decides which ones count)
    seq = [((car,), True), ((car,), True), ((car, ped), True), ((), False), ((car,), True),
           ((), True), ((car,), True)]
    kinds = []
    for i, (contacts, any_collision) in enumerate(seq):
        frame = SimFrame(t=0.05 * i, ego_present=True, lane=lane, lane_pos=net.lane_length[lane] / 2,
                         contacts=contacts, any_collision=any_collision)
        events, state = sensors.detect(state, frame, ego, 0.0)
        kinds.append([(str(e.kind), e.other) for e in events])
    v, p = ("collision_vehicle", "car1"), ("collision_pedestrian", "p0")
    assert kinds == [[v], [v], [v, p], [], [v], [], [v]]


def test_roadside_is_a_contact_on_every_step_off_the_road(grid):
    net, lane, sensors = grid
    x, y, yaw = _lane_point(net, lane)
    on = EgoState(x, y, yaw, 5.0)
    nx, ny = -math.sin(yaw), math.cos(yaw)
    off = EgoState(x + 40.0 * nx, y + 40.0 * ny, yaw, 5.0)  # 40 m to the lane's left
    assert sensors.drivable.count_off([(off.x, off.y)]) == 1
    state, seen = SensorState(), []
    for ego in (on, off, off, on, off):
        frame = SimFrame(t=0.0, ego_present=True, lane="", lane_pos=0.0)
        events, state = sensors.detect(state, frame, ego, 0.0)
        seen.append([str(e.kind) for e in events if e.kind == EventKind.COLLISION_STATIC])
    # a contact with the static layout on every step off the road: the leaderboard's
    # CollisionTest (icrsumo.scoring) counts it again once the ego moved 3 m
    assert seen == [[], ["collision_static"], ["collision_static"], [], ["collision_static"]]


def _drive_through(sensors, lane: str, lights, speeds=None, start: float = 30.0, end: float = 12.0,
                   step: float = 0.5, state: SensorState | None = None):
    """Hand-made frames of the ego driving straight along ``lane``'s last direction from
    ``start`` m before its end to ``end`` m past it, ``step`` m a frame: SUMO's lane is ``lane``
    while the front is before the line, then the straight movement's internal lane.
    ``lights(before) -> tl_states`` and ``speeds(before) -> m/s`` by the centre's distance
    before the line. Returns [(before, [event kinds])] and the last state."""
    net = sensors.net
    line = sensors.stop_line(lane)
    conns = sensors._conns(lane)
    via = next(c for c in conns if c.direction == "s").via
    yaw = math.atan2(line.uy, line.ux)
    half = 0.5 * sensors.size[0]
    state = state or SensorState()
    out = []
    n = int(round((start + end) / step))
    for i in range(n + 1):
        before = start - i * step
        x, y = line.x - before * line.ux, line.y - before * line.uy
        front = before - half
        frame = SimFrame(t=0.05 * i, ego_present=True, lane=lane if front > 0 else via,
                         lane_pos=net.lane_length[lane] - front if front > 0 else -front,
                         tl_states=lights(before))
        speed = speeds(before) if speeds else 5.0
        events, state = sensors.detect(state, frame, EgoState(x, y, yaw, speed), 0.0)
        out.append((before, [str(e.kind) for e in events]))
    return out, state


@pytest.fixture(scope="module")
def signalised(grid):
    net, _, sensors = grid
    lane = next(ln for ln in sorted(net.lane_shape) if not ln.startswith(":") and sensors.tls_ahead(ln)
                and any(c.direction == "s" for c in sensors._conns(ln)))
    (tls,) = sensors.tls_ahead(lane)
    n = 1 + max(c.link_index for conns in net.connections.values() for c in conns if c.tls == tls)
    return sensors, lane, tls, n


def test_red_light_is_charged_when_the_tail_crosses_the_stop_line(signalised):
    sensors, lane, tls, n = signalised
    half = 0.5 * sensors.size[0]
    red, green = {tls: "r" * n}, {tls: "G" * n}
    got, _ = _drive_through(sensors, lane, lambda b: red)
    charged = [b for b, kinds in got if "red_light" in kinds]
    # RunningRedLightTest: the tail segment (0.8 half-lengths to a half-length + 1 m behind the
    # centre) meets the stop line: the first step whose centre is 0.8 half-lengths past it
    assert len(charged) == 1 and -(half + 1.0) <= charged[0] <= -0.8 * half
    assert all(-0.8 * half < b for b, kinds in got if b > charged[0])
    # entered on green, red while the tail is still on the line: charged (judged at the line,
    # not at the junction entry)
    got, _ = _drive_through(sensors, lane, lambda b: red if b < -0.8 * half - 0.3 else green)
    assert sum("red_light" in k for _, k in got) == 1
    # red only once the whole tail is past: not charged
    got, _ = _drive_through(sensors, lane, lambda b: red if b < -(half + 1.0) - 0.01 else green)
    assert not any("red_light" in k for _, k in got)


def test_a_light_is_charged_once_until_another_one_is(signalised):
    sensors, lane, tls, n = signalised
    red = {tls: "r" * n}
    got, state = _drive_through(sensors, lane, lambda b: red)
    assert sum("red_light" in k for _, k in got) == 1 and state.last_red == f"{tls}|{lane.rpartition('_')[0]}"
    again, _ = _drive_through(sensors, lane, lambda b: red, state=state)
    assert not any("red_light" in k for _, k in again)


def test_lights_are_read_only_between_the_junction_entry_and_the_tail_crossing(signalised):
    sensors, lane, tls, n = signalised
    via = next(c for c in sensors._conns(lane) if c.direction == "s").via
    assert sensors.lights_needed(SensorState(prev_lane=lane), lane) == ()
    assert sensors.lights_needed(SensorState(prev_lane=lane), via) == (tls,)
    _, state = _drive_through(sensors, lane, lambda b: {tls: "G" * n}, end=0.0)
    assert state.approach is not None and sensors.lights_needed(state, via) == (tls,)
    _, state = _drive_through(sensors, lane, lambda b: {tls: "G" * n}, state=SensorState())
    assert state.approach is None and sensors.lights_needed(state, via) == ()


@pytest.fixture(scope="module")
def stop_lane():
    net = load_net(bundled_towns()["icr_tjunctions"])
    sensors = Sensors(net, driving_lanes(net), drivable_area(net), (4.6, 1.9))
    lane = next(ln for ln in sorted(net.lane_shape) if sensors.stop_sign(ln)
                and any(c.direction == "s" for c in sensors._conns(ln)) and net.lane_length[ln] > 40)
    return sensors, lane


def test_stop_sign_by_trigger_volume_and_horizon(stop_lane):
    sensors, lane = stop_lane
    volume = 0.9 * sensors.stop_line(lane).width
    kinds = lambda got: [k for _, ks in got for k in ks if k == "stop_sign"]  # noqa: E731
    # no stop: charged once, when the centre leaves the volume over the line
    got, state = _drive_through(sensors, lane, lambda b: {})
    assert kinds(got) == ["stop_sign"] and state.stop is None
    assert next(b for b, k in got if "stop_sign" in k) < 0.0
    # a stop anywhere in the horizon (the volume and the 20 m before it) counts
    for at in (1.0, volume + 19.0):
        got, _ = _drive_through(sensors, lane, lambda b: {},
                                speeds=lambda b, at=at: 0.0 if abs(b - at) < 0.3 else 5.0)
        assert kinds(got) == [], at
    # a stop before the horizon does not
    got, _ = _drive_through(sensors, lane, lambda b: {}, speeds=lambda b: 0.0 if abs(b - 28.0) < 0.3 else 5.0)
    assert kinds(got) == ["stop_sign"]


def test_wrong_way_event_and_the_outside_bits(grid):
    net, lane, sensors = grid
    x, y, yaw = _lane_point(net, lane)
    pos = net.lane_length[lane] / 2
    frame = SimFrame(t=0.0, ego_present=True, lane=lane, lane_pos=pos)
    events, state = sensors.detect(SensorState(), frame, EgoState(x, y, yaw + math.pi, 3.0), 0.0)
    # SUMO's lane against the heading: the (never penalised) wrong_way event; the leaderboard's
    # wrong-lane rule judges lane changes only, so a start against the lane sets no bit
    assert [str(e.kind) for e in events] == ["wrong_way"] and state.wrong and state.outside == 0
    events, state = sensors.detect(state, frame, EgoState(x, y, yaw, 3.0), 0.0)
    assert events == [] and state.outside == 0
    nx, ny = -math.sin(yaw), math.cos(yaw)
    far = SimFrame(t=0.05, ego_present=True, lane="", lane_pos=0.0)
    _, state = sensors.detect(state, far, EgoState(x + 40.0 * nx, y + 40.0 * ny, yaw, 3.0), 0.0)
    assert state.outside & OFF_LANES


def test_background_teleports_are_recorded(grid):
    net, lane, sensors = grid
    x, y, yaw = _lane_point(net, lane)
    frame = SimFrame(t=1.0, ego_present=True, lane=lane, lane_pos=1.0, teleports=("bg1", "bg2"))
    events, _ = sensors.detect(SensorState(), frame, EgoState(x, y, yaw, 3.0), 0.0)
    assert [(str(e.kind), e.other) for e in events] == [("teleport_background", "bg1"),
                                                      ("teleport_background", "bg2")]


@pytest.mark.parametrize("town", sorted(t for t in bundled_towns() if t.startswith("icr_")) + ["Town03"])
def test_drivable_area_cells_give_the_exact_predicate(town):
    net = load_net(bundled_towns()[town])
    area = DrivableArea(drivable_area(net).geometry)  # a fresh memo
    rng = np.random.default_rng(5)
    pts = np.concatenate(list(net.lane_shape.values()))
    near = pts[rng.integers(len(pts), size=4000)] + rng.normal(0.0, 4.0, (4000, 2))
    got = [area.contains(float(x), float(y)) for x, y in near]
    assert got == area.contains_xy(near).tolist()
    assert 0.2 < np.mean(got) < 0.95  # both answers occur near the lanes
    assert not area.contains(float("nan"), 0.0) and not area.contains(math.inf, 0.0)
    assert area.count_off([(1e7, 1e7), (float("nan"), 0.0)]) == 2


def test_drivable_area_holds_junctions_and_not_their_walking_areas():
    net = load_net(bundled_towns()["icr_grid"])
    area = drivable_area(net)
    sn = net.sumolib_net
    walk = [ln for e in sn.getEdges(withInternal=True) if e.getFunction() == "walkingarea"
            for ln in e.getLanes()]
    assert walk, "the grid town has sidewalks"
    from shapely.geometry import Polygon

    inside_walk = [Polygon(ln.getShape()).representative_point() for ln in walk if len(ln.getShape()) >= 3]
    assert not any(area.contains(p.x, p.y) for p in inside_walk)
    tls_nodes = [n for n in sn.getNodes() if n.getType() == "traffic_light"]
    assert tls_nodes
    for node in tls_nodes:
        cx, cy = node.getCoord()[:2]
        assert area.contains(cx, cy), node.getID()  # the middle of a signalised crossroads
