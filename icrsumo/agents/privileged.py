"""Privileged built-in agents: ``route-oracle`` and ``instruction-follower``.

Both drive the same way: plan a lane path ahead on the map (lanes, junction-internal lanes),
track it with waypoints, and set the speed from the speed limit, curvature, the gap to
vehicles and pedestrians on the path, traffic-light states and stop signs. They differ only in
how they choose the next edge at a junction:

- route-oracle follows the scenario's route and ignores the instruction (instruction-blind
  upper bound);
- instruction-follower does not know the route: it classifies the active instruction with the
  intent classifier and takes the branch it names at the next junction (left / right /
  straight; roundabout exit 1 = right, 2 = straight, 3 = left; highway exit = right), changes
  lane when told, and otherwise (follow, unclear) keeps the current road: straight where
  possible, else the only way on, else right.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from ..dynamics import VehicleParams
from ..instructions.intent import classify_intent
from ..networks import Connection, RoadNet, load_net
from ..types import Intent
from .base import Action, EpisodeInfo, Observation, World

COMFORT_DECEL = 3.0      # m/s^2 used to plan stops
LAT_ACCEL = 2.0          # m/s^2 allowed in curves
MIN_GAP = 4.0            # m kept to the vehicle or pedestrian ahead (bumper to bumper)
STOP_MARGIN = 1.0        # m before a stop line (front bumper)
HORIZON = 70.0           # m of path planned ahead
CORRIDOR = 2.0           # m lateral half-width in which an object is "on the path"
STOP_SIGN_WAIT = 1.0     # s stopped at a stop sign before going on
CRUISE_FACTOR = 0.9      # fraction of the speed limit driven


@dataclass
class _Piece:
    lane: str
    a: float
    b: float
    conn: Connection | None = None   # the connection this piece leads into (set on its last normal piece)


@dataclass
class _Path:
    points: np.ndarray                       # (N, 2) m
    cum: np.ndarray                          # (N,) arc length m
    speed: np.ndarray                        # (N,) speed limit m/s
    stops: list[tuple[float, Connection]] = field(default_factory=list)   # (s of stop line, conn)


def _lane_edge(lane: str) -> str:
    return lane.rsplit("_", 1)[0]


def _lane_index(lane: str) -> int:
    return int(lane.rsplit("_", 1)[1])


class PathDriver(ABC):
    """Shared driving logic; subclasses implement :meth:`choose`."""

    name = "path-driver"
    privileged = True

    def __init__(self) -> None:
        self.params = VehicleParams()
        self.net: RoadNet | None = None
        self._decided: dict[str, str] = {}
        self._stopped_at: dict[str, float] = {}
        self._cleared: set[str] = set()
        self._edge = ""

    # ----------------------------------------------------------------- protocol
    def reset(self, info: EpisodeInfo) -> None:
        self.net = load_net(info.net)
        self._decided.clear()
        self._stopped_at.clear()
        self._cleared.clear()
        self._edge = ""

    def act(self, obs: Observation) -> Action:
        w = obs.world
        assert w is not None, "privileged agent without a World view"
        self.observe(obs)
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

    def _plan(self, w: World, lane: str, pos: float) -> _Path:
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
            chain = conn.via_chain[conn.via_chain.index(lane):]
            pieces.append(_Piece(chain[0], pos, net.lane_length[chain[0]]))
            pieces += [_Piece(v, 0.0, net.lane_length[v]) for v in chain[1:]]
            total = sum(p.b - p.a for p in pieces)
            edge, cur, start = dst, conn.to_lane, 0.0
        else:
            edge, cur, start = _lane_edge(lane), _lane_index(lane), pos
            if edge != self._edge:
                self._decided = {k: v for k, v in self._decided.items() if k != self._edge}
                self._edge = edge
        first = True
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
            conns = net.connections[(edge, nxt)]
            allowed = tuple(sorted({c.from_lane for c in conns}))
            want = self.preferred_lane(w, edge, allowed, cur) if first else \
                min(allowed, key=lambda i: (abs(i - cur), i))
            if want != cur and first and not self._lane_free(w, edge, want, start):
                want = cur  # wait for a gap; the lane end acts as a stop point below
            if want != cur:
                shift = float(np.clip(length - start - 5.0, 3.0, 20.0))
                pieces.append(_Piece(f"{edge}_{cur}", start, start))
                start2 = min(start + shift, length)
                conn = min((c for c in conns if c.from_lane == want),
                           key=lambda c: (abs(c.to_lane - c.from_lane), c.to_lane), default=None)
                pieces.append(_Piece(f"{edge}_{want}", start2, length, conn))
                cur = want
            else:
                conn = min((c for c in conns if c.from_lane == cur),
                           key=lambda c: (abs(c.to_lane - c.from_lane), c.to_lane), default=None)
                pieces.append(_Piece(f"{edge}_{cur}", start, length, conn))
            total += length - start
            if conn is None:
                break
            for v in conn.via_chain:
                pieces.append(_Piece(v, 0.0, net.lane_length[v]))
                total += net.lane_length[v]
            edge, cur, start, first = nxt, conn.to_lane, 0.0, False
        return self._make_path(pieces, w)

    def _make_path(self, pieces: list[_Piece], w: World) -> _Path:
        net = self.net
        pts, speeds, stops = [], [], []
        cum = 0.0
        for p in pieces:
            seg = net.lane_slice(p.lane, p.a, max(p.a, p.b))
            lim = net.edge_speed.get(_lane_edge(p.lane), 13.89) if not p.lane.startswith(":") else 13.89
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
        return _Path(points, c, np.array(speeds) if speeds else np.zeros(1), stops)

    def _lane_free(self, w: World, edge: str, lane_index: int, pos: float) -> bool:
        """No vehicle on the target lane near the ego: from 12 m behind to 10 m ahead of its
        front when moving, only the footprint plus 3 m either way when (nearly) stopped."""
        if len(w.vehicles) == 0:
            return True
        lane = f"{edge}_{lane_index}"
        x0, y0, h = self.net.lane_pose(lane, pos)
        d = w.vehicles[:, :2] - np.array([x0, y0])
        lon = d[:, 0] * math.cos(h) + d[:, 1] * math.sin(h)
        lat = -d[:, 0] * math.sin(h) + d[:, 1] * math.cos(h)
        half = 0.5 * w.vehicles[:, 3]
        behind, ahead = (12.0, 10.0) if w.ego.speed > 1.0 else (self.params.length + 3.0, 3.0)
        return not bool(np.any((np.abs(lat) < 1.8) & (lon + half > -behind) & (lon - half < ahead)))

    # ----------------------------------------------------------------- speed
    def _on_path(self, path: _Path, xy: np.ndarray, half: np.ndarray | float) -> np.ndarray:
        """Arc position (m) of each object centre on the path, NaN when off the corridor."""
        if len(xy) == 0 or len(path.points) < 2:
            return np.zeros(0)
        d = np.hypot(xy[:, None, 0] - path.points[None, :, 0], xy[:, None, 1] - path.points[None, :, 1])
        k = d.argmin(axis=1)
        s = path.cum[k]
        near = d[np.arange(len(xy)), k] < (CORRIDOR + half)
        return np.where(near, s, np.nan)

    def _target_speed(self, w: World, path: _Path, t: float) -> float:
        ego = w.ego
        if len(path.points) < 2:
            return 0.0
        # speed limit and curvature over the path, as allowed speeds at the current position
        pts = path.points
        head = np.arctan2(np.diff(pts[:, 1]), np.diff(pts[:, 0]))
        dh = np.abs((np.diff(head) + np.pi) % (2 * np.pi) - np.pi)
        ds = np.maximum(np.diff(path.cum)[1:], 0.5)
        kappa = np.concatenate([[0.0], dh / ds, [0.0]])
        if len(kappa) >= 3:
            kappa = np.convolve(kappa, np.ones(3) / 3, mode="same")
        v_point = np.minimum(path.speed * CRUISE_FACTOR, np.sqrt(LAT_ACCEL / np.maximum(kappa, 1e-4)))
        allowed = np.sqrt(v_point ** 2 + 2 * COMFORT_DECEL * path.cum)
        v = float(allowed.min())
        stop_s = math.inf
        # vehicles and pedestrians on the path
        if len(w.vehicles):
            s = self._on_path(path, w.vehicles[:, :2], 0.5 * w.vehicles[:, 4])
            gaps = s - 0.5 * w.vehicles[:, 3]
            gaps = gaps[np.isfinite(gaps) & (s > 0.5)]
            if len(gaps):
                stop_s = min(stop_s, float(gaps.min()) - MIN_GAP)
        if len(w.pedestrians):
            s = self._on_path(path, w.pedestrians, 0.5)
            s = s[np.isfinite(s) & (s > 0.0)]
            if len(s):
                stop_s = min(stop_s, float(s.min()) - MIN_GAP)
        # traffic lights, stop signs and yielding at minor links
        for s_line, conn in path.stops:
            key = f"{conn.from_edge}_{conn.from_lane}>{conn.via}"
            if conn.tls:
                state = w.tl_states.get(conn.tls, "")
                ch = state[conn.link_index] if 0 <= conn.link_index < len(state) else "G"
                must_stop = ch in "rRu" or (ch in "yY" and s_line > ego.speed ** 2 / (2 * 6.0))
                if must_stop or ch == "g" and self._junction_busy(w, conn):
                    stop_s = min(stop_s, s_line - STOP_MARGIN)
                continue
            if conn.state in ("s", "w") and key not in self._cleared:
                if s_line - STOP_MARGIN < 3.0 and ego.speed < 0.1:
                    since = self._stopped_at.setdefault(key, t)
                    if t - since >= STOP_SIGN_WAIT and not self._junction_busy(w, conn):
                        self._cleared.add(key)
                        continue
                stop_s = min(stop_s, s_line - STOP_MARGIN)
            elif conn.state == "m" and s_line < 20.0 and self._junction_busy(w, conn):
                stop_s = min(stop_s, s_line - STOP_MARGIN)
        if math.isfinite(stop_s):
            v = min(v, math.sqrt(2 * COMFORT_DECEL * max(0.0, stop_s)))
            if stop_s < 0.5:
                v = 0.0
        return max(0.0, v)

    def _junction_busy(self, w: World, conn: Connection) -> bool:
        """Another vehicle is inside or within 12 m of the junction's internal lanes."""
        if len(w.vehicles) == 0 or not conn.via:
            return False
        shape = self.net.lane_shape[conn.via]
        c = shape.mean(axis=0)
        d = np.hypot(w.vehicles[:, 0] - c[0], w.vehicles[:, 1] - c[1])
        ego_d = math.hypot(w.ego.x - c[0], w.ego.y - c[1])
        return bool(np.any((d < 12.0) & (d < ego_d + 6.0)))

    # ----------------------------------------------------------------- output
    def _waypoints(self, w: World, path: _Path) -> np.ndarray:
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


class RouteOracle(PathDriver):
    """Follows the scenario's route; ignores the instruction (an instruction-blind upper bound)."""

    name = "route-oracle"
    #: the only agent handed the route (World.route); every other one gets None
    needs_route = True

    def choose(self, w: World, edge: str, options: list[str], tentative: bool) -> str | None:
        edges = w.route.edges if w.route is not None else ()
        # the edge's first occurrence on the route (the bundled routes never revisit an edge)
        for i, e in enumerate(edges[:-1]):
            if e == edge:
                return edges[i + 1]
        return None


class InstructionFollower(PathDriver):
    """Knows the map, not the route: takes the branch the active instruction names."""

    name = "instruction-follower"

    def __init__(self) -> None:
        super().__init__()
        self.intent = Intent.FOLLOW
        self._instr_id = -1
        self._lane_done: set[int] = set()
        self._lane_at_instr: int | None = None
        self._ring_exits = 0
        self._ring_edge = ""

    def reset(self, info: EpisodeInfo) -> None:
        super().reset(info)
        self.intent = Intent.FOLLOW
        self._instr_id = -1
        self._lane_done = set()
        self._lane_at_instr = None
        self._ring_exits = 0
        self._ring_edge = ""

    def observe(self, obs: Observation) -> None:
        if obs.instruction_id != self._instr_id:
            self._instr_id = obs.instruction_id
            self.intent = classify_intent(obs.instruction) if obs.instruction else Intent.FOLLOW
            self._lane_at_instr = None

    def preferred_lane(self, w: World, edge: str, lanes: tuple[int, ...], current: int) -> int:
        if self.intent in (Intent.LANE_LEFT, Intent.LANE_RIGHT) and self._instr_id not in self._lane_done:
            if self._lane_at_instr is None:
                self._lane_at_instr = current
            elif current != self._lane_at_instr:
                self._lane_done.add(self._instr_id)
                return super().preferred_lane(w, edge, lanes, current)
            step = 1 if self.intent == Intent.LANE_LEFT else -1
            if current + step in lanes:
                return current + step
            if current + step in self.net.passenger_lanes.get(edge, ()):
                return current  # the lane exists but does not lead on: stay
        return super().preferred_lane(w, edge, lanes, current)

    def choose(self, w: World, edge: str, options: list[str], tentative: bool) -> str | None:
        net = self.net
        if len(options) == 1:
            return options[0]
        ring = net.roundabout_edges
        if edge in ring:
            if edge != self._ring_edge:
                self._ring_edge = edge
            target = {Intent.RIGHT: 1, Intent.STRAIGHT: 2, Intent.LEFT: 3}.get(self.intent, 2)
            exits = [o for o in options if o not in ring]
            on_ring = [o for o in options if o in ring]
            if exits and (self._ring_exits + 1 >= target or not on_ring):
                if not tentative:
                    self._ring_exits = 0
                return exits[0]
            if exits and not tentative:
                self._ring_exits += 1
            return on_ring[0] if on_ring else options[0]
        dirs = {o: {c.direction for c in net.connections[(edge, o)]} for o in options}
        want = {Intent.LEFT: ("l", "L"), Intent.RIGHT: ("r", "R"), Intent.STRAIGHT: ("s",)}.get(self.intent)
        if want:
            for d in want:
                for o in options:
                    if d in dirs[o]:
                        return o
        for d in ("s", "L", "R", "r", "l"):
            for o in options:
                if d in dirs[o]:
                    return o
        return options[0]
