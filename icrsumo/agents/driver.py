"""The privileged agents' driving: :class:`PathDriver` plans a lane path ahead on the map (lanes,
junction-internal lanes, lane changes where a gap allows), tracks it with waypoints, and drives
it at the speed :class:`~icrsumo.agents.speed.SpeedPolicy` sets. Subclasses choose the next edge
at each junction (the agents of :mod:`icrsumo.agents.privileged`)."""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from icrsumo.world.dynamics import VehicleParams
from icrsumo.world.networks import Connection, RoadNet, load_net, polyline_cumlen

from .base import Action, EpisodeInfo, Observation, World
from .conflicts import ConflictMap, project
from .speed import LINE_HOLD_SPEED, UNSEEN_SPEED, PlannedPath, SpeedPolicy, known_speeds

HORIZON = 70.0           # m of path planned ahead
LANE_CHANGE_M = 20.0     # m of road over which one lane is changed (less where the edge is short)
WAIT_BEFORE_END = 12.0   # m before an edge's end where the ego waits for a gap to change lanes
CHANGE_GAP_TIME = 3.0    # s a vehicle coming up behind on the target lane must be away at its closing speed
CHANGE_LOOK_BEHIND = 80.0  # m behind the ego's rear within which such vehicles are checked


@dataclass
class _Piece:
    """One stretch of the planned path: lane ``lane`` from ``a`` to ``b`` m."""

    lane: str
    a: float
    b: float
    conn: Connection | None = None   # the connection this piece leads into (set on its last normal piece)
    enter: Connection | None = None  # the connection whose internal lanes begin here (junction entry)
    entered: float = 0.0             # m of ``enter``'s internal lanes already behind this piece's start


def lane_edge(lane: str) -> str:
    """The edge of SUMO lane id ``lane`` (``EDGE_INDEX``)."""
    return lane.rsplit("_", 1)[0]


def lane_index(lane: str) -> int:
    """The index of SUMO lane id ``lane`` (``EDGE_INDEX``) on its edge, 0 the rightmost."""
    return int(lane.rsplit("_", 1)[1])


class PathDriver(SpeedPolicy, ABC):
    """Shared driving logic: the lane path ahead, its waypoints and (:class:`SpeedPolicy`) its
    speed; subclasses implement :meth:`choose`."""

    name = "path-driver"
    privileged = True

    def __init__(self) -> None:
        self.params = VehicleParams()
        self.net: RoadNet | None = None
        self._decided: dict[str, str] = {}
        self._stopped_at: dict[str, float] = {}
        self._cleared: set[str] = set()
        self._edge = ""
        # the lane change in progress: (edge, target lane index, lane position where it ends, m)
        self._change: tuple[str, int, float] | None = None
        self._conflict_map: ConflictMap | None = None
        # other vehicles' speeds (m/s), estimated from their positions at the previous call
        self._seen: tuple[float, np.ndarray] | None = None
        self._speeds = np.zeros(0)
        self._ped_seen: tuple[float, np.ndarray] | None = None
        self._ped_speeds = np.zeros(0)
        # junction id -> when the ego, standing, began to wait for a standing queue head (s)
        self._queue_wait: dict[str, float] = {}
        self._now = 0.0

    # ----------------------------------------------------------------- protocol
    def reset(self, info: EpisodeInfo) -> None:
        self.net = load_net(info.net)
        self._decided.clear()
        self._stopped_at.clear()
        self._cleared.clear()
        self._edge = ""
        self._change = None
        self._seen = None
        self._speeds = np.zeros(0)
        self._ped_seen = None
        self._ped_speeds = np.zeros(0)
        self._queue_wait.clear()
        self._now = 0.0

    def act(self, obs: Observation) -> Action:
        w = obs.world
        assert w is not None, "privileged agent without a World view"
        self.observe(obs)
        self._track(obs.t, w.vehicles, w.pedestrians)
        self._now = obs.t
        if w.ego.speed > LINE_HOLD_SPEED:   # driving on: the waits at junctions are over
            self._queue_wait.clear()
        lane, pos = self._locate(w)
        if not lane:
            return Action(waypoints=np.array([[2.0, 0.0], [4.0, 0.0]]), target_speed=0.0)
        path = self._plan(w, lane, pos)
        v = self._target_speed(w, path, obs.t)
        return Action(waypoints=self._waypoints(w, path), target_speed=v)

    # ----------------------------------------------------------------- hooks
    def observe(self, obs: Observation) -> None:  # noqa: B027 (optional hook)
        """Read the instruction (subclasses that listen to it)."""

    @abstractmethod
    def choose(self, w: World, edge: str, options: list[str], tentative: bool) -> str | None:
        """The next edge after ``edge`` among ``options`` (None: stop at the edge's end)."""

    def entered(self, w: World, edge: str) -> None:  # noqa: B027 (optional hook)
        """The ego has just been found on normal edge ``edge`` (subclasses that track where
        they are on a route)."""

    def preferred_lane(self, w: World, edge: str, lanes: tuple[int, ...], current: int) -> int:
        """Lane index to drive on ``edge`` when the next edge allows several."""
        return current if current in lanes else min(lanes, key=lambda i: (abs(i - current), i))

    # ----------------------------------------------------------------- planning
    def _locate(self, w: World) -> tuple[str, float]:
        net = self.net
        if w.lane and (w.lane in net.lane_shape):
            return w.lane, w.lane_pos
        fx, fy = w.ego.front(self.params.length)
        best = None
        for lane, pos, dist, heading in net.project(fx, fy, 4.0):
            d_ang = abs((heading - w.ego.yaw + math.pi) % (2 * math.pi) - math.pi)
            if d_ang < math.pi / 2 and (best is None or dist < best[2]):
                best = (lane, pos, dist)
        return (best[0], best[1]) if best else ("", 0.0)

    def _nearest_via(self, w: World, conns: tuple[Connection, ...]) -> tuple[str, float]:
        """The internal lane (and position on it, m) of ``conns`` nearest the ego's front."""
        fx, fy = w.ego.front(self.params.length)
        best = ("", 0.0, math.inf)
        for c in conns:
            for v in c.via_chain:
                shape = self.net.lane_shape[v]
                d = np.hypot(shape[:, 0] - fx, shape[:, 1] - fy)
                k = int(d.argmin())
                if d[k] < best[2]:
                    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(shape, axis=0).T))])
                    best = (v, float(cum[k]), float(d[k]))
        return best[0], best[1]

    def _options(self, edge: str) -> list[str]:
        net = self.net
        return [s for s in net.successors.get(edge, ())
                if any(c.direction != "t" for c in net.connections[(edge, s)])] or \
            list(net.successors.get(edge, ()))

    def _plan(self, w: World, lane: str, pos: float) -> PlannedPath:
        net = self.net
        pieces: list[_Piece] = []
        total = 0.0
        if lane.startswith(":"):
            src, dst = net.via_edges.get(lane, ("", ""))
            if self._decided.get(src, dst) != dst and (src, self._decided[src]) in net.connections:
                # SUMO maps an ego at a junction entry onto any of the overlapping internal
                # lanes; keep to the connection this agent committed to
                lane, pos = self._nearest_via(w, net.connections[(src, self._decided[src])])
                dst = self._decided[src]
            conn = next((c for c in net.connections.get((src, dst), ()) if lane in c.via_chain), None)
            if conn is None:
                return self._make_path([_Piece(lane, pos, net.lane_length[lane])], w)
            k = conn.via_chain.index(lane)
            chain = conn.via_chain[k:]
            behind = sum(net.lane_length[v] for v in conn.via_chain[:k]) + pos
            pieces.append(_Piece(chain[0], pos, net.lane_length[chain[0]], enter=conn, entered=behind))
            pieces += [_Piece(v, 0.0, net.lane_length[v]) for v in chain[1:]]
            total = sum(p.b - p.a for p in pieces)
            edge, cur, start = dst, conn.to_lane, 0.0
        else:
            edge, cur, start = lane_edge(lane), lane_index(lane), pos
            if edge != self._edge:
                self._decided = {k: v for k, v in self._decided.items() if k != self._edge}
                self._edge = edge
                self._change = None
                self.entered(w, edge)
        first = True
        hold = first_line = math.inf
        while total < HORIZON and edge in net.passenger_lanes:
            length = net.edge_length[edge]
            options = self._options(edge)
            tentative = not first or (length - start) > 15.0
            nxt = self._decided.get(edge)
            if nxt is None and options:
                nxt = self.choose(w, edge, options, tentative)
                if nxt is not None and not tentative:
                    self._decided[edge] = nxt
            if nxt is None or (edge, nxt) not in net.connections:
                pieces.append(_Piece(f"{edge}_{cur}", start, length))
                break
            conns = self._onward(w, edge, nxt)
            allowed = tuple(sorted({c.from_lane for c in conns}))
            want = self.preferred_lane(w, edge, allowed, cur) if first else \
                min(allowed, key=lambda i: (abs(i - cur), i))
            if want != cur:
                step = 1 if want > cur else -1
                committed = first and self._change is not None and self._change[:2] == (edge, cur + step) \
                    and not self._coming_up(w, edge, cur + step, start)
                if first and not committed and not self._lane_free(w, edge, cur + step, start):
                    # wait for a gap: no way on from this lane, so stop where the change still fits
                    self._change = None   # and begin the change afresh once there is one
                    pieces.append(_Piece(f"{edge}_{cur}", start, length))
                    hold = total + max(0.0, length - start - WAIT_BEFORE_END)
                    break
                if first:   # mid-change the ego may reach its old lane's end (stop lines stagger)
                    first_line = total + min(net.lane_length[f"{edge}_{k}"] for k in
                                             range(min(cur, want), max(cur, want) + 1)) - start
                ends = self._change_ends(edge, cur, want, start, length, first, committed)
                pieces.append(_Piece(f"{edge}_{cur}", start, start))
                pieces += [_Piece(f"{edge}_{cur + step * (k + 1)}", e, e) for k, e in enumerate(ends[:-1])]
                conn = min((c for c in conns if c.from_lane == want),
                           key=lambda c: (abs(c.to_lane - c.from_lane), c.to_lane), default=None)
                pieces.append(_Piece(f"{edge}_{want}", ends[-1], length, conn))
                cur = want
            else:
                conn = min((c for c in conns if c.from_lane == cur),
                           key=lambda c: (abs(c.to_lane - c.from_lane), c.to_lane), default=None)
                pieces.append(_Piece(f"{edge}_{cur}", start, length, conn))
            total += length - start
            if conn is None:
                break
            for i, v in enumerate(conn.via_chain):
                pieces.append(_Piece(v, 0.0, net.lane_length[v], enter=conn if i == 0 else None))
                total += net.lane_length[v]
            edge, cur, start, first = nxt, conn.to_lane, 0.0, False
        path = self._make_path(pieces, w)
        path.hold = hold
        # mid-change, the first junction's stop line is the nearest of the lanes' ends
        if math.isfinite(first_line) and not lane.startswith(":"):
            first_edge = lane_edge(lane)
            path.stops = [(min(s_line, first_line) if c.from_edge == first_edge else s_line, c)
                          for s_line, c in path.stops]
        return path

    def _onward(self, w: World, edge: str, nxt: str) -> tuple[Connection, ...]:
        """The connections ``edge`` -> ``nxt`` that land on a lane of ``nxt`` with a connection
        to the edge after it (all of them when none does): the lane is chosen one junction ahead,
        as a driver does where the next edge is too short to change lanes on."""
        net = self.net
        conns = net.connections[(edge, nxt)]
        nxt2 = self._decided.get(nxt)
        if nxt2 is None:
            options = self._options(nxt)
            nxt2 = self.choose(w, nxt, options, True) if options else None
        if nxt2 is None or (nxt, nxt2) not in net.connections:
            return conns
        good = {c.from_lane for c in net.connections[(nxt, nxt2)]}
        return tuple(c for c in conns if c.to_lane in good) or conns

    def _change_ends(self, edge: str, cur: int, want: int, start: float, length: float,
                     first: bool, committed: bool) -> list[float]:
        """Lane positions (m) where each one-lane step of a change ``cur`` -> ``want`` on ``edge``
        ends. The first step of a change under way (``committed``) keeps its end: a replan from
        the lane SUMO reports must not push the goal ahead, or the change never completes."""
        n = abs(want - cur)
        step = float(np.clip((length - start - 5.0) / n, 3.0, LANE_CHANGE_M))
        ends: list[float] = []
        e = start
        for k in range(n):
            if k == 0 and committed and self._change[2] - start > 2.0:
                e = self._change[2]
            else:
                e = min(e + step, length)
            ends.append(e)
        if first:
            self._change = (edge, cur + (1 if want > cur else -1), ends[0])
        return ends

    def _make_path(self, pieces: list[_Piece], w: World) -> PlannedPath:
        net = self.net
        pts, speeds, stops, junctions = [], [], [], []
        cum = 0.0
        for p in pieces:
            if p.enter is not None:
                junctions.append((cum - p.entered, p.enter))
            seg = net.lane_slice(p.lane, p.a, max(p.a, p.b))
            lim = net.edge_speed.get(lane_edge(p.lane), 13.89) if not p.lane.startswith(":") else 13.89
            for q in seg:
                if pts:
                    d = math.hypot(q[0] - pts[-1][0], q[1] - pts[-1][1])
                    if d < 1e-3:
                        continue
                    cum += d
                pts.append((float(q[0]), float(q[1])))
                speeds.append(lim)
            if p.conn is not None and (p.conn.tls or p.conn.state in ("s", "w", "m")):
                stops.append((cum, p.conn))
        points = np.array(pts) if pts else np.zeros((1, 2))
        c = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))]) if len(points) > 1 \
            else np.zeros(1)
        return PlannedPath(points, c, np.array(speeds) if speeds else np.zeros(1), stops, junctions=junctions)

    def _lane_free(self, w: World, edge: str, lane_index: int, pos: float) -> bool:
        """No vehicle on the target lane near the ego (from 12 m behind to 10 m ahead of its
        front when moving, only the footprint plus 3 m either way when (nearly) stopped), and
        none coming up from behind too fast (:meth:`_coming_up`): a gap is judged by time, not
        distance alone, or a car 10 m back at 12 m/s runs into a change begun from a standstill."""
        if len(w.vehicles) == 0:
            return True
        x0, y0, h = self.net.lane_pose(f"{edge}_{lane_index}", pos)
        c, s = math.cos(h), math.sin(h)
        d = w.vehicles[:, :2] - np.array([x0, y0])
        lon, lat = d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c
        half = 0.5 * w.vehicles[:, 3]
        behind, ahead = (12.0, 10.0) if w.ego.speed > 1.0 else (self.params.length + 3.0, 3.0)
        # on the target lane, or between it and the ego (a car changing lanes towards it)
        ego_lat = -(w.ego.x - x0) * s + (w.ego.y - y0) * c
        lo, hi = sorted((-1.8 * np.sign(ego_lat), 0.7 * ego_lat))
        lane_band = (np.abs(lat) < 1.8) | ((lat > lo) & (lat < hi))
        if np.any(lane_band & (lon + half > -behind) & (lon - half < ahead)):
            return False
        return not self._coming_up(w, edge, lane_index, pos)

    def _coming_up(self, w: World, edge: str, lane_index: int, pos: float) -> bool:
        """Whether a vehicle on lane ``lane_index`` of ``edge`` comes up from behind the ego
        (front at lane position ``pos`` m) and would reach its rear within
        :data:`CHANGE_GAP_TIME` s at its closing speed. Checked again during a change while
        SUMO still has the ego on its old lane: the car behind does not see it yet."""
        if len(w.vehicles) == 0:
            return False
        lane = f"{edge}_{lane_index}"
        scale = self.net.lane_length[lane] / max(float(polyline_cumlen(self.net.lane_shape[lane])[-1]), 1e-9)
        # along the lane's own polyline (on a curved lane a car 25 m back lies metres off the
        # straight line through the ego's position), and back along the ways into it: near the
        # start of a short lane the car coming up is still on the internal lane before it
        # (carla_fidelity_revisit_014: a 9 m edge, the car 20 m back inside the junction before)
        s_v = np.full(len(w.vehicles), np.nan)
        for path, cum, start in self._map().approaches(lane):
            s = project(path, cum, w.vehicles[:, :2], w.vehicles[:, 2], corridor=1.8) - start
            s_v = np.where(np.isnan(s_v), np.where(s > 0.0, s * scale, s), s_v)
        half = 0.5 * w.vehicles[:, 3]
        speeds = known_speeds(self._speeds, len(w.vehicles))
        closing = np.where(np.isfinite(speeds), speeds, UNSEEN_SPEED) - w.ego.speed
        gap = pos - self.params.length - (s_v + half)   # its front to the ego's rear, m
        coming = np.isfinite(gap) & (gap > 0.0) & (gap < CHANGE_LOOK_BEHIND) & \
            (gap < CHANGE_GAP_TIME * closing)
        return bool(coming.any())

    # ----------------------------------------------------------------- output
    def _waypoints(self, w: World, path: PlannedPath) -> np.ndarray:
        ego = w.ego
        c, s = math.cos(ego.yaw), math.sin(ego.yaw)
        d = path.points - np.array([ego.x, ego.y])
        fwd = d[:, 0] * c + d[:, 1] * s
        left = -d[:, 0] * s + d[:, 1] * c
        keep = fwd > 0.5
        wps = np.stack([fwd[keep], left[keep]], axis=1)
        if len(wps) < 2:
            wps = np.array([[2.0, 0.0], [4.0, 0.0]])
        return wps
