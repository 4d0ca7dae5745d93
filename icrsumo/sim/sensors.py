"""Pure sensors of the closed loop: what happened to the ego at one step, from the road
network's geometry and SUMO's :class:`~icrsumo.sim.frame.SimFrame`. No libsumo, no raster.

* :func:`footprint_corners` / :func:`off_corners`: the ego's rectangle (m);
* :class:`LaneHeading`: a lane's heading (rad) at a lane position;
* :class:`Sensors.detect`: ``(state, frame, ego, pos) -> (events, state)``, the infraction
  events of one step (a contact event per actor on every step of contact, for the
  leaderboard's collision rule in :mod:`icrsumo.scoring`; roadside from the drivable area's
  polygons (:mod:`icrsumo.sim.drivable`); red lights and stop signs at junction entry; wrong
  way) and the step's OutsideRouteLanesTest flags (:mod:`icrsumo.sim.lanes`) in a frozen
  :class:`SensorState`. Route progress is the run-ending monitor's
  (:mod:`icrsumo.scoring.criteria`).

Infractions come from the network and SUMO's state only, never from what the agent sees.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from icrsumo.core.types import Event
from icrsumo.core.vocab import EventKind
from icrsumo.scoring.criteria import OFF_LANES, OFF_LANES_LB2, WRONG_LANE, WRONG_LANE_LB2
from icrsumo.scoring.route import angle_diff
from icrsumo.world.dynamics import EgoState
from icrsumo.world.networks import RoadNet

from .drivable import DrivableArea
from .frame import NO_LIGHTS, SimFrame
from .lanes import ALLOWED_OUT_DISTANCE_LB2, DrivingLanes, WrongLaneState, wrong_lane_step

#: an approach to a stop sign counts as stopped below this speed (m/s) within this distance (m)
STOP_SPEED, STOP_ZONE = 0.1, 15.0
#: wrong way: heading off the lane direction by more than this (rad)
WRONG_WAY_RAD = math.radians(100.0)
#: m past a junction entry after which SUMO's internal lane names the ego's movement (at the
#: entry, movements from one lane share their first metres and SUMO may report any of them)
MOVEMENT_KNOWN_M = 15.0


@dataclass(frozen=True)
class PendingLight:
    """A junction entered at (``x``, ``y``) m while the lights of the movements from the
    approach lane disagreed: ``red`` / ``not_red``, the edges those movements lead to. Light
    ``tls``'s red is charged once the ego's own movement is known (:meth:`Sensors.detect`)."""

    x: float
    y: float
    tls: str
    red: frozenset[str]
    not_red: frozenset[str]


def footprint_corners(st: EgoState, size: tuple[float, float]) -> np.ndarray:
    """The ego footprint's four corners (4, 2) m; ``size`` = (length, width) m."""
    c, s = math.cos(st.yaw), math.sin(st.yaw)
    hl, hw = 0.5 * size[0], 0.5 * size[1]
    local = np.array([[hl, hw], [hl, -hw], [-hl, -hw], [-hl, hw]])
    return np.stack([st.x + local[:, 0] * c - local[:, 1] * s, st.y + local[:, 0] * s + local[:, 1] * c], 1)


def off_corners(st: EgoState, size: tuple[float, float], count_off) -> int:
    """How many corners of the ego footprint (:func:`footprint_corners`, same arithmetic) are off the
    drivable area (``count_off(points) -> int``: :meth:`DrivableArea.count_off`)."""
    c, s = math.cos(st.yaw), math.sin(st.yaw)
    hl, hw = 0.5 * size[0], 0.5 * size[1]
    x, y = st.x, st.y
    return count_off([(x + lx * c - ly * s, y + lx * s + ly * c)
                      for lx, ly in ((hl, hw), (hl, -hw), (-hl, -hw), (-hl, hw))])


class LaneHeading:
    """Lane heading (rad) at a lane position: ``RoadNet.lane_pose(lane, pos)[2]`` with the
    per-lane tables built once (same cumulative lengths, same segment choice)."""

    def __init__(self, net: RoadNet) -> None:
        self.net = net
        self._tables: dict[str, tuple | None] = {}

    def _table(self, lane: str) -> tuple | None:
        shape = self.net.lane_shape[lane]
        if len(shape) < 2:
            return None
        cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(shape, axis=0).T))])
        heads = [math.atan2(shape[k + 1][1] - shape[k][1], shape[k + 1][0] - shape[k][0])
                 for k in range(len(shape) - 1)]
        return cum.tolist(), float(cum[-1]), max(self.net.lane_length[lane], 1e-9), heads

    def __call__(self, lane: str, pos: float) -> float:
        tab = self._tables.get(lane, False)
        if tab is False:
            tab = self._tables[lane] = self._table(lane)
        if tab is None:
            return self.net.lane_pose(lane, pos)[2]
        cum, total, length, heads = tab
        s = min(max(pos * total / length, 0.0), total)
        k = min(max(bisect.bisect_right(cum, s) - 1, 0), len(heads) - 1)
        return heads[k]


@dataclass(frozen=True)
class SensorState:
    """The sensors' memory after a step. ``outside`` holds this step's OutsideRouteLanesTest
    bits (:mod:`icrsumo.sim.lanes`): :data:`~icrsumo.scoring.criteria.OFF_LANES` /
    :data:`~icrsumo.scoring.criteria.WRONG_LANE` by Leaderboard 1.0's rules, ``OFF_LANES_LB2`` /
    ``WRONG_LANE_LB2`` by 2.0's; ``lane_state`` / ``lane_state_lb2``: the wrong-lane memories;
    ``speed_limit``: the speed limit (m/s) of the nearest driving lane;
    ``prev_lane``: the last lane SUMO placed the ego on; ``stopped``: lanes whose stop zone the
    ego stood in since it entered them; ``roadside`` / ``wrong``: footprint off the drivable
    area / heading against SUMO's lane at this step; ``lights``: the states at this step of the
    lights controlling the connections from ``prev_lane`` (the next step's red-light check);
    ``pending``: a junction entry whose red light waits for the movement to be known."""

    outside: int = 0
    lane_state: WrongLaneState = WrongLaneState()
    lane_state_lb2: WrongLaneState = WrongLaneState()
    speed_limit: float = 0.0
    prev_lane: str = ""
    stopped: frozenset[str] = frozenset()
    roadside: bool = False
    wrong: bool = False
    lights: Mapping[str, str] = field(default_factory=lambda: NO_LIGHTS)
    pending: PendingLight | None = None


class Sensors:
    """The static side of the sensors for one network: lane headings, the driving lanes
    (:class:`~icrsumo.sim.lanes.DrivingLanes`), the drivable area and the ego's size
    ``(length, width)`` m. :meth:`detect` is pure given its arguments (the caches only memoise
    lookups)."""

    def __init__(self, net: RoadNet, lanes: DrivingLanes, drivable: DrivableArea,
                 size: tuple[float, float]) -> None:
        self.net, self.lanes = net, lanes
        self.drivable, self.size = drivable, size
        self.heading = LaneHeading(net)
        self._tls_ahead: dict[str, tuple[str, ...]] = {}

    def tls_ahead(self, lane: str) -> tuple[str, ...]:
        """Traffic lights of the connections from ``lane`` (none when it is junction-internal)."""
        got = self._tls_ahead.get(lane)
        if got is None:
            out: set[str] = set()
            if lane and not lane.startswith(":"):
                edge, _, idx = lane.rpartition("_")
                i = int(idx)
                for nxt in self.net.successors.get(edge, ()):
                    out.update(c.tls for c in self.net.connections[(edge, nxt)]
                               if c.tls and c.from_lane == i)
            got = self._tls_ahead[lane] = tuple(sorted(out))
        return got

    def lights_needed(self, state: SensorState, lane: str) -> tuple[str, ...]:
        """The lights whose states :meth:`detect` needs in the frame in which SUMO reports the
        ego on ``lane`` ("" off every lane), after ``state``: those ahead of the lane it then
        remembers."""
        return self.tls_ahead(lane or state.prev_lane)

    def detect(self, state: SensorState, frame: SimFrame, ego: EgoState,
               pos: float) -> tuple[list[Event], SensorState]:
        """The events of the step ``frame`` (the ego present) with the ego at ``ego`` (centre,
        yaw, speed) and at route position ``pos`` (m), and the sensors' state after it. Events
        come in this order: collisions (one per actor in contact, every step of contact), red
        light / stop sign, roadside, wrong way, background teleports."""
        t, lane, lane_pos = frame.t, frame.lane, frame.lane_pos
        ev: list[Event] = []
        for c in frame.contacts:
            kind = EventKind.COLLISION_PEDESTRIAN if c.pedestrian else EventKind.COLLISION_VEHICLE
            ev.append(Event(kind, t, pos, c.other, ego.x, ego.y))
        net = self.net
        stopped = state.stopped
        # stop-sign bookkeeping: stopped within the last STOP_ZONE m of a lane
        if lane and not lane.startswith(":") and ego.speed < STOP_SPEED and \
                net.lane_length.get(lane, 0.0) - lane_pos <= STOP_ZONE and lane not in stopped:
            stopped = stopped | {lane}
        prev = state.prev_lane
        pending = state.pending
        if prev and not prev.startswith(":") and lane.startswith(":"):
            pending = None
            edge = prev.rsplit("_", 1)[0]
            idx = int(prev.rsplit("_", 1)[1])
            conns = [c for nxt in net.successors.get(edge, ()) for c in net.connections[(edge, nxt)]
                     if c.from_lane == idx]
            entered = next((c for c in conns if c.via == lane), None)
            if entered is not None and entered.tls:
                red = {c.to_edge for c in conns if c.tls and self._red(state.lights, c.tls, c.link_index)}
                rest = {c.to_edge for c in conns if c.to_edge not in red}
                if red and not rest:
                    ev.append(Event(EventKind.RED_LIGHT, t, pos, entered.tls, ego.x, ego.y))
                elif red:   # the movements from this lane disagree: wait to see which one it is
                    pending = PendingLight(ego.x, ego.y, entered.tls, frozenset(red), frozenset(rest))
            elif entered is not None and entered.state in ("s", "w") and prev not in stopped:
                ev.append(Event(EventKind.STOP_SIGN, t, pos, net.edge_to_node.get(edge, ""), ego.x, ego.y))
        if pending is not None and lane:
            if not lane.startswith(":"):
                to_edge = lane.rsplit("_", 1)[0]
            elif math.hypot(ego.x - pending.x, ego.y - pending.y) >= MOVEMENT_KNOWN_M:
                to_edge = net.via_edges.get(lane, ("", ""))[1]
            else:
                to_edge = None
            if to_edge is not None:
                if to_edge in pending.red and to_edge not in pending.not_red:
                    ev.append(Event(EventKind.RED_LIGHT, t, pos, pending.tls, ego.x, ego.y))
                pending = None
        if lane and lane != prev and not lane.startswith(":") and lane in stopped:
            stopped = stopped - {lane}  # a fresh approach to this lane's end
        # roadside: the footprint left the drivable area (two corners or more off it)
        off = off_corners(ego, self.size, self.drivable.count_off) >= 2
        if off and not state.roadside:
            ev.append(Event(EventKind.COLLISION_STATIC, t, pos, "roadside", ego.x, ego.y))
        # wrong way against SUMO's lane (recorded, never penalised)
        wrong = False
        if lane and lane in net.lane_shape:
            wrong = angle_diff(self.heading(lane, lane_pos), ego.yaw) > WRONG_WAY_RAD
        if wrong and not state.wrong:
            ev.append(Event(EventKind.WRONG_WAY, t, pos, lane, ego.x, ego.y))
        if frame.teleports:
            ev += [Event(EventKind.TELEPORT_BACKGROUND, t, pos, vid) for vid in frame.teleports]
        # OutsideRouteLanesTest's lane facts
        point = self.lanes.nearest(ego.x, ego.y)
        lane_state = wrong_lane_step(state.lane_state, point, ego.yaw)
        lane_state2 = wrong_lane_step(state.lane_state_lb2, point, ego.yaw, lb2=True)
        outside = ((OFF_LANES if self.lanes.off_lanes(point) else 0) | (WRONG_LANE if lane_state.wrong else 0)
                   | (OFF_LANES_LB2 if self.lanes.off_lanes(point, ALLOWED_OUT_DISTANCE_LB2) else 0)
                   | (WRONG_LANE_LB2 if lane_state2.wrong else 0))
        prev_lane = lane or prev
        # the lights the next step's red-light check reads: those ahead of prev_lane, now
        tls = self.tls_ahead(prev_lane)
        lights = {tl: frame.tl_states[tl] for tl in tls} if tls else NO_LIGHTS
        return ev, SensorState(outside, lane_state, lane_state2, point.speed_limit, prev_lane, stopped, off,
                               wrong, lights, pending)

    @staticmethod
    def _red(lights: Mapping[str, str], tls: str, link_index: int) -> bool:
        sig = lights.get(tls, "")
        return 0 <= link_index < len(sig) and sig[link_index] in "rR"
