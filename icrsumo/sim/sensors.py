"""Pure sensors of the closed loop: what happened to the ego at one step, from the road
network's geometry and SUMO's :class:`~icrsumo.sim.frame.SimFrame`. No libsumo, no raster.

* :class:`RouteProjection`: progress along the route polyline (m) and distance to it;
* :func:`footprint_corners` / :func:`off_corners`: the ego's rectangle (m);
* :class:`LaneHeading`: a lane's heading (rad) at a lane position;
* :class:`Sensors.detect`: ``(state, frame, ego) -> (events, state)``, the infraction
  events of one step (collisions de-duplicated per actor contact, roadside from the drivable
  area's polygons (:mod:`icrsumo.sim.drivable`), red lights and stop signs at junction entry,
  wrong way) and the per-step readings (progress, route distance, outside the route's lanes)
  in a frozen :class:`SensorState`.

Infractions come from the network and SUMO's state only, never from what the agent sees.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ..dynamics import EgoState
from ..networks import RoadNet
from ..types import Event
from ..vocab import EventKind
from .drivable import DrivableArea
from .frame import NO_LIGHTS, SimFrame

#: an approach to a stop sign counts as stopped below this speed (m/s) within this distance (m)
STOP_SPEED, STOP_ZONE = 0.1, 15.0
#: wrong way: heading off the lane direction by more than this (rad)
WRONG_WAY_RAD = math.radians(100.0)


#: routes with at most this many segments are projected in plain Python (numpy's per-call
#: overhead dominates on a few segments), longer ones on arrays
_SMALL_ROUTE = 48
#: relative slack of the squared-distance preselection in RouteProjection._locate_small
_PRESELECT = 1e-9


class RouteProjection:
    """The route polyline with windowed projection (progress) and distance queries.

    :meth:`locate` runs every simulation step. Its values are those of the plain per-segment
    formula evaluated on arrays (``t = clip(((p - a) . ab) / max(|ab|^2, 1e-9), 0, 1)``,
    ``d = hypot(a + ab t - p)``), bit for bit: the same floating-point operations in the same
    order, with distances from ``np.hypot``."""

    def __init__(self, poly: np.ndarray) -> None:
        self.a = poly[:-1]
        self.b = poly[1:]
        ab = self.b - self.a
        self.len = np.hypot(ab[:, 0], ab[:, 1])
        self.ab = ab
        self.cum = np.concatenate([[0.0], np.cumsum(self.len)])
        self.total = float(self.cum[-1])
        self._a2 = np.ascontiguousarray(self.a.T)     # (2, N): x row, y row
        self._ab2 = np.ascontiguousarray(ab.T)
        self._den = np.maximum(self.len ** 2, 1e-9)
        self._cum_list = self.cum.tolist()
        self._len_list = self.len.tolist()
        self._segs = list(zip(self.a[:, 0].tolist(), self.a[:, 1].tolist(), ab[:, 0].tolist(),
                              ab[:, 1].tolist(), self._den.tolist()))

    def _window(self, progress: float) -> tuple[int, int]:
        """Segments k in [lo, hi) with cum[k + 1] >= progress - 20 and cum[k] <= progress + 40
        (a contiguous range: cum is non-decreasing)."""
        cum = self._cum_list
        lo = bisect.bisect_left(cum, progress - 20.0, 1) - 1
        hi = min(bisect.bisect_right(cum, progress + 40.0), len(cum) - 1)
        return lo, hi

    def locate(self, x: float, y: float, progress: float) -> tuple[float, float]:
        """(route position near ``progress``, distance to the whole route) in m: the nearest
        projection among the segments within [progress - 20, progress + 40] m if it is within
        15 m (else ``progress``), and the distance to the nearest point of the route."""
        if len(self._segs) <= _SMALL_ROUTE:
            return self._locate_small(x, y, progress)
        p = np.array(((x,), (y,)))
        pa = (p - self._a2) * self._ab2
        t = pa[0] + pa[1]
        t /= self._den
        np.maximum(t, 0.0, out=t)                    # = np.clip(t, 0, 1), t is never NaN
        np.minimum(t, 1.0, out=t)
        q = self._ab2 * t
        q += self._a2
        q -= p
        d_all = np.hypot(q[0], q[1])
        lo, hi = self._window(progress)
        if lo < hi:
            k = lo + int(d_all[lo:hi].argmin())
            s_here = self._cum_list[k] + t.item(k) * self._len_list[k] if d_all.item(k) < 15.0 else progress
        else:
            s_here = progress
        return s_here, float(d_all.min())

    def _locate_small(self, x: float, y: float, progress: float) -> tuple[float, float]:
        """:meth:`locate` in plain Python. Distances come from ``np.hypot``, but only for the
        segments whose squared distance is within a relative 1e-9 of the smallest (of the
        window, of the route): the others are farther by far more than hypot's rounding, so
        the argmin (first minimum) and the minimum are those of the full array."""
        lo, hi = self._window(progress)
        ts, qs, e2 = [], [], []
        for ax, ay, abx, aby, den in self._segs:
            t = ((x - ax) * abx + (y - ay) * aby) / den
            t = 0.0 if t < 0.0 else 1.0 if t > 1.0 else t
            qx, qy = ax + abx * t - x, ay + aby * t - y
            ts.append(t)
            qs.append((qx, qy))
            e2.append(qx * qx + qy * qy)
        dist = [math.nan] * len(e2)
        hypot = np.hypot
        best = []
        for a, b in ((lo, hi), (0, len(e2))):
            if a >= b:
                best.append(-1)
                continue
            cut = min(e2[a:b])
            cut = cut * (1.0 + _PRESELECT) if cut >= 1e-280 else math.inf  # tiny squares: all
            k_best, d_best = -1, math.inf
            for k in range(a, b):
                if e2[k] <= cut:
                    d = dist[k]
                    if d != d:  # not computed yet
                        d = dist[k] = float(hypot(*qs[k]))
                    if d < d_best:
                        k_best, d_best = k, d
            best.append(k_best)
        k = best[0]
        near = k >= 0 and dist[k] < 15.0
        return (self._cum_list[k] + ts[k] * self._len_list[k] if near else progress), dist[best[1]]


def footprint_corners(st: EgoState, size: tuple[float, float]) -> np.ndarray:
    """The ego footprint's four corners (4, 2) m; ``size`` = (length, width) m."""
    c, s = math.cos(st.yaw), math.sin(st.yaw)
    hl, hw = 0.5 * size[0], 0.5 * size[1]
    local = np.array([[hl, hw], [hl, -hw], [-hl, -hw], [-hl, hw]])
    return np.stack([st.x + local[:, 0] * c - local[:, 1] * s, st.y + local[:, 0] * s + local[:, 1] * c], 1)


def angle_diff(a: float, b: float) -> float:
    """|a - b| wrapped to [0, pi] (rad)."""
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


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
    """The sensors' memory after a step. ``progress`` (m, monotone: the furthest route position
    reached), ``route_dist`` (m, ego centre to the route) and ``outside`` (the ego is off the
    route's lanes or driving the wrong way) are this step's readings; ``prev_lane``: the last
    lane SUMO placed the ego on; ``touching``: actors in contact; ``stopped``: lanes whose stop
    zone the ego stood in since it entered them; ``roadside`` / ``wrong``: footprint off the
    drivable area / wrong way at this step; ``lights``: the states at this step of the lights
    controlling the connections from ``prev_lane`` (the next step's red-light check)."""

    progress: float = 0.0
    route_dist: float = 0.0
    outside: bool = False
    prev_lane: str = ""
    touching: frozenset[str] = frozenset()
    stopped: frozenset[str] = frozenset()
    roadside: bool = False
    wrong: bool = False
    lights: Mapping[str, str] = field(default_factory=lambda: NO_LIGHTS)


class Sensors:
    """The static side of the sensors for one route on one network: route projection, lane
    headings, the drivable area, the route's edges and the ego's size ``(length, width)`` m.
    :meth:`detect` is pure given its arguments (the caches only memoise lookups)."""

    def __init__(self, net: RoadNet, route: RouteProjection, route_edges: frozenset[str],
                 drivable: DrivableArea, size: tuple[float, float]) -> None:
        self.net, self.route, self.route_edges = net, route, frozenset(route_edges)
        self.drivable, self.size = drivable, size
        self.heading = LaneHeading(net)
        self._inside: dict[str, bool] = {}
        self._tls_ahead: dict[str, tuple[str, ...]] = {}

    def inside(self, lane: str) -> bool:
        """Whether ``lane`` belongs to the route (a junction lane: both its edges do)."""
        got = self._inside.get(lane)
        if got is None:
            got = self._inside[lane] = self._inside_uncached(lane)
        return got

    def _inside_uncached(self, lane: str) -> bool:
        if not lane:
            return False
        if lane.startswith(":"):
            a, b = self.net.via_edges.get(lane, ("", ""))
            return a in self.route_edges and b in self.route_edges
        return lane.rsplit("_", 1)[0] in self.route_edges

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

    def detect(self, state: SensorState, frame: SimFrame, ego: EgoState) -> tuple[list[Event], SensorState]:
        """The events of the step ``frame`` (the ego present) with the ego at ``ego`` (centre,
        yaw, speed), and the sensors' state after it. Events come in this order: collisions,
        red light / stop sign, roadside, wrong way, background teleports."""
        t, lane, lane_pos = frame.t, frame.lane, frame.lane_pos
        s_here, rdist = self.route.locate(ego.x, ego.y, state.progress)
        pos = max(state.progress, s_here)
        ev: list[Event] = []
        touching = state.touching
        if frame.any_collision:  # contacts are refreshed on steps where SUMO reports collisions
            now = set()
            for c in frame.contacts:
                now.add(c.other)
                if c.other not in state.touching:
                    kind = EventKind.COLLISION_PEDESTRIAN if c.pedestrian else EventKind.COLLISION_VEHICLE
                    ev.append(Event(kind, t, pos, c.other, ego.x, ego.y))
            touching = frozenset(now)
        net = self.net
        stopped = state.stopped
        # stop-sign bookkeeping: stopped within the last STOP_ZONE m of a lane
        if lane and not lane.startswith(":") and ego.speed < STOP_SPEED and \
                net.lane_length.get(lane, 0.0) - lane_pos <= STOP_ZONE and lane not in stopped:
            stopped = stopped | {lane}
        prev = state.prev_lane
        if prev and not prev.startswith(":") and lane.startswith(":"):
            edge = prev.rsplit("_", 1)[0]
            idx = int(prev.rsplit("_", 1)[1])
            for nxt in net.successors.get(edge, ()):
                for c in net.connections[(edge, nxt)]:
                    if c.from_lane == idx and c.via == lane:
                        if c.tls:
                            sig = state.lights.get(c.tls, "")
                            if 0 <= c.link_index < len(sig) and sig[c.link_index] in "rR":
                                ev.append(Event(EventKind.RED_LIGHT, t, pos, c.tls, ego.x, ego.y))
                        elif c.state in ("s", "w") and prev not in stopped:
                            ev.append(Event(EventKind.STOP_SIGN, t, pos, net.edge_to_node.get(edge, ""),
                                            ego.x, ego.y))
        if lane and lane != prev and not lane.startswith(":") and lane in stopped:
            stopped = stopped - {lane}  # a fresh approach to this lane's end
        # roadside: the footprint left the drivable area (two corners or more off it)
        off = off_corners(ego, self.size, self.drivable.count_off) >= 2
        if off and not state.roadside:
            ev.append(Event(EventKind.COLLISION_STATIC, t, pos, "roadside", ego.x, ego.y))
        # wrong way
        wrong = False
        if lane and lane in net.lane_shape:
            wrong = angle_diff(self.heading(lane, lane_pos), ego.yaw) > WRONG_WAY_RAD
        if wrong and not state.wrong:
            ev.append(Event(EventKind.WRONG_WAY, t, pos, lane, ego.x, ego.y))
        if frame.teleports:
            ev += [Event(EventKind.TELEPORT_BACKGROUND, t, pos, vid) for vid in frame.teleports]
        prev_lane = lane or prev
        # the lights the next step's red-light check reads: those ahead of prev_lane, now
        tls = self.tls_ahead(prev_lane)
        lights = {tl: frame.tl_states[tl] for tl in tls} if tls else NO_LIGHTS
        new = SensorState(pos, rdist, not self.inside(lane) or wrong, prev_lane, touching, stopped, off,
                          wrong, lights)
        return ev, new
