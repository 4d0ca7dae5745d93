"""Pure sensors of the closed loop: what happened to the ego at one step, from the road
network's geometry and SUMO's :class:`~icrsumo.sim.frame.SimFrame`. No libsumo, no raster.

* :func:`footprint_corners` / :func:`off_corners`: the ego's rectangle (m);
* :class:`LaneHeading`: a lane's heading (rad) at a lane position;
* :class:`StopLine`: the end of an approach lane, where its stop line lies;
* :class:`Sensors.detect`: ``(state, frame, ego, pos) -> (events, state)``, the infraction
  events of one step (a contact event per actor on every step of contact, the roadside too,
  for the leaderboard's collision rule in :mod:`icrsumo.scoring`; roadside from the drivable
  area's polygons (:mod:`icrsumo.sim.drivable`); red lights when the ego's tail crosses the
  stop line, stop signs when the ego leaves the sign's trigger volume, as scenario_runner's
  ``RunningRedLightTest`` and ``RunningStopTest`` judge them (branch leaderboard-1.0,
  ``srunner/scenariomanager/scenarioatomics/atomic_criteria.py``); wrong way) and the step's
  OutsideRouteLanesTest flags (:mod:`icrsumo.sim.lanes`) in a frozen :class:`SensorState`.
  Route progress is the run-ending monitor's (:mod:`icrsumo.scoring.criteria`).

Infractions come from the network and SUMO's state only, never from what the agent sees.
:data:`~icrsumo.core.defaults.LOOP_VERSION` names these rules (with the monitor's); an out
folder records it, so episodes detected by other rules are never mixed into one table.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import LineString

from icrsumo.core.types import Event
from icrsumo.core.vocab import EventKind
from icrsumo.scoring.criteria import OFF_LANES, OFF_LANES_LB2, WRONG_LANE, WRONG_LANE_LB2
from icrsumo.scoring.route import angle_diff
from icrsumo.world.dynamics import EgoState
from icrsumo.world.networks import RoadNet

from .drivable import DrivableArea
from .frame import SimFrame
from .lanes import ALLOWED_OUT_DISTANCE_LB2, DrivingLanes, WrongLaneState, wrong_lane_step

#: RunningStopTest: a stop counts below this speed (m/s) ...
STOP_SPEED = 0.1
#: ... on any step while the sign's trigger volume lies within the ego's horizon: its centre
#: and the 20 lane points 1 m apart ahead of it (m)
STOP_HORIZON_M = 20.0
#: a stop sign's trigger volume: the last 0.9 lane widths (m) of the approach lane before its
#: stop line (CARLA 0.9.10 generates a cube of 90 % of the lane width at the sign)
STOP_VOLUME_LANE_WIDTHS = 0.9
#: RunningRedLightTest: the ego's tail is the segment from 0.8 half-lengths behind its centre
#: to a half-length + 1 m behind it ...
TAIL_NEAR_HALF_LENGTHS, TAIL_FAR_EXTRA_M = 0.8, 1.0
#: ... and an approach's stop line spans 0.4 lane widths either side of the lane's centre
STOP_LINE_HALF_WIDTHS = 0.4
#: m past the junction entry after which an approach whose stop line the tail never crossed
#: (the ego drove out over the line's ends) is forgotten
APPROACH_FORGET_M = 30.0
#: wrong way: heading off the lane direction by more than this (rad)
WRONG_WAY_RAD = math.radians(100.0)
#: m past a junction entry after which SUMO's internal lane names the ego's movement (at the
#: entry, movements from one lane share their first metres and SUMO may report any of them)
MOVEMENT_KNOWN_M = 15.0


@dataclass(frozen=True)
class PendingLight:
    """A junction entered at (``x``, ``y``) m whose stop line the tail crossed while the lights
    of the movements from the approach lane disagreed: ``red`` / ``not_red``, the edges those
    movements lead to. Light ``key``'s red is charged once the ego's own movement is known
    (:meth:`Sensors.detect`)."""

    x: float
    y: float
    tls: str
    red: frozenset[str]
    not_red: frozenset[str]
    key: str = ""


@dataclass(frozen=True)
class Approach:
    """A junction entered at (``x``, ``y``) m from signalised approach ``lane`` (light ``tls``)
    whose stop line the ego's tail has not crossed yet."""

    lane: str
    x: float
    y: float
    tls: str

    @property
    def key(self) -> str:
        """The light as the leaderboard counts it once: the junction's signal and this approach
        edge."""
        return f"{self.tls}|{self.lane.rpartition('_')[0]}"


@dataclass(frozen=True)
class StopTarget:
    """A stop sign whose trigger volume (at the end of approach ``lane``, junction ``node``) is
    within the ego's horizon: whether the ego ``stopped`` since, and whether its centre was
    ever inside the volume (``affected``)."""

    lane: str
    node: str
    stopped: bool = False
    affected: bool = False


@dataclass(frozen=True)
class StopLine:
    """Where approach lane's stop line lies: the lane's end (``x``, ``y``) m, its direction there
    (``ux``, ``uy``, a unit vector) and its ``width`` (m)."""

    x: float
    y: float
    ux: float
    uy: float
    width: float

    def before(self, x: float, y: float) -> float:
        """How far (m) the point (``x``, ``y``) lies before the line, along the lane (< 0 past it)."""
        return (self.x - x) * self.ux + (self.y - y) * self.uy

    def crossed_by(self, ax: float, ay: float, bx: float, by: float) -> bool:
        """Whether segment a-b meets the stop line: the segment across the lane at its end,
        :data:`STOP_LINE_HALF_WIDTHS` lane widths either side of the centre (the leaderboard's
        ``is_vehicle_crossing_line`` asks shapely the same of the two lines)."""
        half = STOP_LINE_HALF_WIDTHS * self.width
        nx, ny = -self.uy, self.ux
        dx, dy = half * nx, half * ny
        line = LineString([(self.x - dx, self.y - dy), (self.x + dx, self.y + dy)])
        return bool(shapely.intersects(LineString([(ax, ay), (bx, by)]), line))


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
    ``prev_lane``: the last lane SUMO placed the ego on; ``roadside`` / ``wrong``: footprint off
    the drivable area / heading against SUMO's lane at this step; ``approach``: a signalised
    junction entry whose stop line the tail has not crossed; ``pending``: a red light waiting
    for the movement to be known; ``last_red``: the light (``tls|approach edge``) charged last,
    which is not charged again until another one is; ``stop``: the stop sign in the ego's
    horizon."""

    outside: int = 0
    lane_state: WrongLaneState = WrongLaneState()
    lane_state_lb2: WrongLaneState = WrongLaneState()
    speed_limit: float = 0.0
    prev_lane: str = ""
    roadside: bool = False
    wrong: bool = False
    approach: Approach | None = None
    pending: PendingLight | None = None
    last_red: str = ""
    stop: StopTarget | None = None


@dataclass(frozen=True)
class _LaneExit:
    """What leaves a normal lane: its connections, their traffic lights (sorted) and the junction
    whose stop sign it approaches ("" none)."""

    conns: tuple
    tls: tuple[str, ...]
    stop_node: str


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
        self._exits: dict[str, _LaneExit] = {}
        self._stop_lines: dict[str, StopLine] = {}

    def _exit(self, lane: str) -> _LaneExit:
        """What leaves normal lane ``lane`` (nothing from a junction-internal one), looked up once."""
        got = self._exits.get(lane)
        if got is None:
            conns: tuple = ()
            if lane and not lane.startswith(":"):
                edge, _, idx = lane.rpartition("_")
                i = int(idx)
                conns = tuple(c for nxt in self.net.successors.get(edge, ())
                              for c in self.net.connections[(edge, nxt)] if c.from_lane == i)
            stops = lane in self.net.lane_shape and any(c.state in ("s", "w") for c in conns)
            got = self._exits[lane] = _LaneExit(
                conns, tuple(sorted({c.tls for c in conns if c.tls})),
                self.net.edge_to_node.get(lane.rpartition("_")[0], "") if stops else "")
        return got

    def _conns(self, lane: str) -> tuple:
        """The connections from normal lane ``lane`` (none from a junction-internal one)."""
        return self._exit(lane).conns

    def tls_ahead(self, lane: str) -> tuple[str, ...]:
        """Traffic lights of the connections from ``lane`` (none when it is junction-internal)."""
        return self._exit(lane).tls

    def lights_needed(self, state: SensorState, lane: str) -> tuple[str, ...]:
        """The lights whose states :meth:`detect` needs in the frame in which SUMO reports the
        ego on ``lane`` ("" off every lane), after ``state``: the light of a junction entered
        whose stop line the tail has not crossed, or entered in this frame (from
        ``state.prev_lane``); none elsewhere."""
        if state.approach is not None:
            return (state.approach.tls,)
        prev = state.prev_lane
        if prev and not prev.startswith(":") and lane.startswith(":"):
            return self.tls_ahead(prev)
        return ()

    def stop_line(self, lane: str) -> StopLine:
        """The stop line at the end of normal lane ``lane``."""
        got = self._stop_lines.get(lane)
        if got is None:
            shape = self.net.lane_shape[lane]
            (x0, y0), (x1, y1) = shape[-2], shape[-1]
            n = math.hypot(x1 - x0, y1 - y0) or 1.0
            width = float(self.net.sumolib_net.getLane(lane).getWidth())
            got = self._stop_lines[lane] = StopLine(float(x1), float(y1), (x1 - x0) / n, (y1 - y0) / n, width)
        return got

    def stop_sign(self, lane: str) -> str:
        """The junction whose stop sign normal lane ``lane`` approaches ("" none): a connection
        from the lane with SUMO's stop (``s``) or all-way stop (``w``) state."""
        return self._exit(lane).stop_node

    def _tail(self, ego: EgoState) -> tuple[float, float, float, float]:
        """The ego's tail segment (RunningRedLightTest's): near end, far end (m)."""
        half = 0.5 * self.size[0]
        c, s = math.cos(ego.yaw), math.sin(ego.yaw)
        near, far = TAIL_NEAR_HALF_LENGTHS * half, half + TAIL_FAR_EXTRA_M
        return ego.x - near * c, ego.y - near * s, ego.x - far * c, ego.y - far * s

    def _red_light(self, state: SensorState, frame: SimFrame, ego: EgoState, t: float, pos: float,
                   ev: list[Event]) -> tuple[Approach | None, PendingLight | None, str]:
        """RunningRedLightTest over SUMO's signals: the approach, pending light and last charged
        light after this step, a RED_LIGHT event appended to ``ev`` when one is charged."""
        approach, pending, last = state.approach, state.pending, state.last_red
        lane, prev = frame.lane, state.prev_lane
        if approach is None and prev and not prev.startswith(":") and lane.startswith(":"):
            entered = next((c for c in self._conns(prev) if c.via == lane), None)
            if entered is not None and entered.tls:
                approach = Approach(prev, ego.x, ego.y, entered.tls)
        if approach is not None:
            line = self.stop_line(approach.lane)
            ax, ay, bx, by = self._tail(ego)
            key = approach.key
            ahead = math.cos(ego.yaw) * line.ux + math.sin(ego.yaw) * line.uy > 0
            if key != last and ahead and line.crossed_by(ax, ay, bx, by):
                conns = self._conns(approach.lane)
                red = {c.to_edge for c in conns if c.tls and self._red(frame.tl_states, c.tls, c.link_index)}
                rest = {c.to_edge for c in conns if c.to_edge not in red}
                if red and not rest:
                    ev.append(Event(EventKind.RED_LIGHT, t, pos, approach.tls, ego.x, ego.y))
                    last, approach = key, None
                elif red:   # the movements from this lane disagree: wait to see which one it is
                    pending = PendingLight(approach.x, approach.y, approach.tls, frozenset(red),
                                           frozenset(rest), key)
                    approach = None
            if approach is not None and (line.before(bx, by) < 0.0 or math.hypot(
                    ego.x - approach.x, ego.y - approach.y) > APPROACH_FORGET_M):
                approach = None  # the whole tail passed the line (or the ego left it far behind)
        if pending is not None and lane:
            if not lane.startswith(":"):
                to_edge = lane.rsplit("_", 1)[0]
            elif math.hypot(ego.x - pending.x, ego.y - pending.y) >= MOVEMENT_KNOWN_M:
                to_edge = self.net.via_edges.get(lane, ("", ""))[1]
            else:
                to_edge = None
            if to_edge is not None:
                if to_edge in pending.red and to_edge not in pending.not_red and pending.key != last:
                    ev.append(Event(EventKind.RED_LIGHT, t, pos, pending.tls, ego.x, ego.y))
                    last = pending.key
                pending = None
        return approach, pending, last

    def _stop_sign(self, state: SensorState, frame: SimFrame, ego: EgoState, t: float, pos: float,
                   ev: list[Event]) -> StopTarget | None:
        """RunningStopTest over a trigger volume at the end of the approach lane: the stop sign
        in the horizon after this step, a STOP_SIGN event appended to ``ev`` when the ego left
        the horizon of a volume its centre entered without having stopped."""
        lane, stop = frame.lane, state.stop
        if stop is None:
            node = self.stop_sign(lane)
            if node and angle_diff(self.heading(lane, frame.lane_pos), ego.yaw) < 0.5 * math.pi:
                line = self.stop_line(lane)
                before = line.before(ego.x, ego.y)
                if 0.0 <= before <= STOP_VOLUME_LANE_WIDTHS * line.width + STOP_HORIZON_M:
                    return StopTarget(lane, node)
            return None
        line = self.stop_line(stop.lane)
        before = line.before(ego.x, ego.y)
        stopped = stop.stopped or ego.speed < STOP_SPEED
        affected = stop.affected or 0.0 <= before <= STOP_VOLUME_LANE_WIDTHS * line.width
        in_horizon = (0.0 <= before <= STOP_VOLUME_LANE_WIDTHS * line.width + STOP_HORIZON_M
                      and (lane == stop.lane or not lane or lane.startswith(":")))
        if in_horizon:
            return StopTarget(stop.lane, stop.node, stopped, affected)
        if affected and not stopped:
            ev.append(Event(EventKind.STOP_SIGN, t, pos, stop.node, ego.x, ego.y))
        return None

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
        approach, pending, last_red = self._red_light(state, frame, ego, t, pos, ev)
        stop = self._stop_sign(state, frame, ego, t, pos, ev)
        net = self.net
        # roadside: the footprint off the drivable area (two corners or more off it), a contact
        # with the static layout on every step of it (CollisionTest counts it again every 3 m)
        off = off_corners(ego, self.size, self.drivable.count_off) >= 2
        if off:
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
        return ev, SensorState(outside, lane_state, lane_state2, point.speed_limit, lane or state.prev_lane,
                               off, wrong, approach, pending, last_red, stop)

    @staticmethod
    def _red(lights: Mapping[str, str], tls: str, link_index: int) -> bool:
        sig = lights.get(tls, "")
        return 0 <= link_index < len(sig) and sig[link_index] in "rR"
