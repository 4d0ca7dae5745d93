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
import re
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from ..dynamics import VehicleParams
from ..instructions.intent import classify_intent
from ..networks import Connection, RoadNet, load_net, polyline_cumlen
from ..types import Intent
from .base import Action, EpisodeInfo, Observation, World
from .conflicts import Conflict, ConflictMap, junction_of, project

COMFORT_DECEL = 3.0      # m/s^2 used to plan stops
HARD_DECEL = 6.0         # m/s^2 the ego can brake with when it must (a conflict point inside a junction)
STOP_LAG = 1.0           # m/s the planned stopping speed is lowered by (the PI controller trails it)
LAT_ACCEL = 2.0          # m/s^2 allowed in curves
MIN_GAP = 4.0            # m kept to the vehicle or pedestrian ahead (bumper to bumper)
STOP_MARGIN = 1.0        # m before a stop line (front bumper)
HORIZON = 70.0           # m of path planned ahead
CORRIDOR = 2.0           # m lateral half-width in which an object is "on the path"
STOP_SIGN_WAIT = 1.0     # s stopped at a stop sign before going on
CRUISE_FACTOR = 0.9      # fraction of the speed limit driven
LANE_CHANGE_M = 20.0     # m of road over which one lane is changed (less where the edge is short)
WAIT_BEFORE_END = 12.0   # m before an edge's end where the ego waits for a gap to change lanes
YIELD_LOOKAHEAD = 60.0   # m ahead within which junction entries are checked for traffic to yield to
YIELD_APPROACH = 35.0    # m from a conflict point within which a vehicle with the right of way is waited for
CONFLICT_CLEAR = 3.0     # m before a conflict point where the ego's front stops
MERGE_MARGIN = 3.0       # m: a vehicle this much farther from a merge than the ego still goes first
MOVING = 0.5             # m/s above which another vehicle counts as moving
YIELD_TIME = 4.0         # s from a conflict point within which a vehicle with the right of way is waited for
UNSEEN_SPEED = 15.0      # m/s assumed for a vehicle not seen at the previous call
MINOR_ENTRY_SPEED = 6.0  # m/s at most when entering a junction on a minor link (g, m)
YIELD_MARGIN = 2.0       # s the ego keeps between clearing a conflict point and a rival reaching it
CHANGE_GAP_TIME = 3.0    # s a vehicle coming up behind on the target lane must be away at its closing speed
CHANGE_LOOK_BEHIND = 80.0  # m behind the ego's rear within which such vehicles are checked
PED_MOVING = 0.3         # m/s above which a pedestrian counts as walking
STANDING_CLEAR = 0.25    # m beyond the ego's half width within which a standing car's body is in its way
SWEPT_MARGIN = 0.5       # m beyond the ego's half width within which a standing pedestrian is in its way
FOE_ACCEL = 2.6          # m/s^2 a foe is assumed to accelerate with (SUMO's default passenger car)
FOE_TOP_SPEED = 13.89    # m/s a foe accelerates to at most when its arrival is estimated
QUEUE_HEAD_M = 10.0      # m before the junction within which a standing car's front heads its queue
STANDING_WAIT = 6.0      # s the ego waits, standing, for standing queue heads before ignoring them
LINE_HOLD = 2.0          # m past the junction entry within which a slow ego still holds at the line
LINE_HOLD_SPEED = 3.0    # m/s below which an ego just past the entry holds rather than creeping on


def arrival_time(dist: np.ndarray, speed: np.ndarray, accel: float = FOE_ACCEL,
                 top: float = FOE_TOP_SPEED) -> np.ndarray:
    """Seconds a vehicle at ``speed`` (m/s) needs to cover ``dist`` (m), both (N,),
    accelerating at ``accel`` (m/s^2) up to ``top`` m/s (or keeping a higher speed)."""
    v = np.maximum(speed, 0.0)
    cruise = np.maximum(v, top)
    t_top = np.maximum(cruise - v, 0.0) / accel               # s to reach top speed
    d_top = (cruise ** 2 - v ** 2) / (2 * accel)                # m covered meanwhile
    t_acc = (np.sqrt(v ** 2 + 2 * accel * np.maximum(dist, 0.0)) - v) / accel
    return np.where(dist <= d_top, t_acc, t_top + (dist - d_top) / cruise)


def _known(speeds: np.ndarray, n: int) -> np.ndarray:
    """``speeds`` (m/s) when they belong to the ``n`` objects seen now, else (n,) NaN."""
    return speeds if len(speeds) == n else np.full(n, np.nan)


def _speeds_since(seen: tuple[float, np.ndarray] | None, t: float, xy: np.ndarray) -> np.ndarray:
    """Speed (m/s) of each point of ``xy`` ((N, 2) m at time ``t`` s) from the nearest point of
    ``seen`` = (time s, (M, 2) m) within 3 m; NaN where none is (or nothing was seen)."""
    speeds = np.full(len(xy), np.nan)
    if seen is not None and len(xy) and len(seen[1]) and t > seen[0]:
        d = xy[:, None, :] - seen[1][None, :, :]
        near = np.hypot(d[..., 0], d[..., 1]).min(axis=1)
        speeds = np.where(near < 3.0, near / (t - seen[0]), np.nan)
    return speeds


@dataclass
class _Piece:
    lane: str
    a: float
    b: float
    conn: Connection | None = None   # the connection this piece leads into (set on its last normal piece)
    enter: Connection | None = None  # the connection whose internal lanes begin here (junction entry)
    entered: float = 0.0             # m of ``enter``'s internal lanes already behind this piece's start


@dataclass
class _Path:
    points: np.ndarray                       # (N, 2) m
    cum: np.ndarray                          # (N,) arc length m
    speed: np.ndarray                        # (N,) speed limit m/s
    stops: list[tuple[float, Connection]] = field(default_factory=list)   # (s of stop line, conn)
    hold: float = math.inf                   # s (m) where the ego must stop: no way on from its lane yet
    junctions: list[tuple[float, Connection]] = field(default_factory=list)  # (s of junction entry, conn)


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

    def _track(self, t: float, vehicles: np.ndarray, pedestrians: np.ndarray | None = None) -> None:
        """Estimate each vehicle's and pedestrian's speed (m/s) from the nearest position seen
        at the previous call (they carry no ids here; between calls 0.1 s apart they move far
        less than they stand apart); NaN for one with no neighbour within 3 m then."""
        xy = vehicles[:, :2] if len(vehicles) else np.zeros((0, 2))
        self._speeds = _speeds_since(self._seen, t, xy)
        self._seen = (t, xy.copy())
        people = pedestrians if pedestrians is not None and len(pedestrians) else np.zeros((0, 2))
        self._ped_speeds = _speeds_since(self._ped_seen, t, people)
        self._ped_seen = (t, people.copy())

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
            k = conn.via_chain.index(lane)
            chain = conn.via_chain[k:]
            behind = sum(net.lane_length[v] for v in conn.via_chain[:k]) + pos
            pieces.append(_Piece(chain[0], pos, net.lane_length[chain[0]], enter=conn, entered=behind))
            pieces += [_Piece(v, 0.0, net.lane_length[v]) for v in chain[1:]]
            total = sum(p.b - p.a for p in pieces)
            edge, cur, start = dst, conn.to_lane, 0.0
        else:
            edge, cur, start = _lane_edge(lane), _lane_index(lane), pos
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
            first_edge = _lane_edge(lane)
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

    def _make_path(self, pieces: list[_Piece], w: World) -> _Path:
        net = self.net
        pts, speeds, stops, junctions = [], [], [], []
        cum = 0.0
        for p in pieces:
            if p.enter is not None:
                junctions.append((cum - p.entered, p.enter))
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
        return _Path(points, c, np.array(speeds) if speeds else np.zeros(1), stops, junctions=junctions)

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
        speeds = _known(self._speeds, len(w.vehicles))
        closing = np.where(np.isfinite(speeds), speeds, UNSEEN_SPEED) - w.ego.speed
        gap = pos - self.params.length - (s_v + half)   # its front to the ego's rear, m
        coming = np.isfinite(gap) & (gap > 0.0) & (gap < CHANGE_LOOK_BEHIND) & \
            (gap < CHANGE_GAP_TIME * closing)
        return bool(coming.any())

    # ----------------------------------------------------------------- speed
    def _on_path(self, path: _Path, xy: np.ndarray, half: np.ndarray | float) -> np.ndarray:
        """Arc position (m) of each object centre projected on the path, NaN off the corridor."""
        if len(xy) == 0:
            return np.zeros(0)
        return project(path.points, path.cum, xy, corridor=CORRIDOR + half)

    def _corners_on_path(self, path: _Path, vehicles: np.ndarray, margin: np.ndarray) -> np.ndarray:
        """Arc position (m) on the path of each corner of each vehicle's footprint ((N, 4);
        NaN for a corner outside the ego's swept path, half its width + ``margin`` (N,) m)."""
        x, y, yaw, hl, hw = (vehicles[:, 0], vehicles[:, 1], vehicles[:, 2], 0.5 * vehicles[:, 3],
                             0.5 * vehicles[:, 4])
        c, s = np.cos(yaw), np.sin(yaw)
        lon = np.array([1.0, 1.0, -1.0, -1.0])[None, :] * hl[:, None]
        lat = np.array([1.0, -1.0, -1.0, 1.0])[None, :] * hw[:, None]
        pts = np.stack([x[:, None] + lon * c[:, None] - lat * s[:, None],
                        y[:, None] + lon * s[:, None] + lat * c[:, None]], axis=-1)
        reach = np.repeat(0.5 * self.params.width + margin, 4)
        return project(path.points, path.cum, pts.reshape(-1, 2), corridor=reach).reshape(len(vehicles), 4)

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
            # a moving car counts within CORRIDOR of the path; a standing one only where its
            # body reaches into the ego's own width (+ STANDING_CLEAR): passing a car that waits
            # beside the path, at a merge say, breaks a stand-off in which each waits for the other
            v_f = _known(self._speeds, len(w.vehicles))
            still = np.isfinite(v_f) & (v_f <= MOVING)
            half_w = 0.5 * w.vehicles[:, 4]
            standing_reach = 0.5 * self.params.width + STANDING_CLEAR - CORRIDOR + half_w
            s = self._on_path(path, w.vehicles[:, :2], np.where(still, standing_reach, half_w))
            gaps = np.where(np.isfinite(s) & (s > 0.5), s - 0.5 * w.vehicles[:, 3], np.inf)
            # a car at an angle to the path (part-way through a turn) reaches into it with a
            # corner while its centre lies outside the corridor: its nearest corner on the path
            corners = self._corners_on_path(path, w.vehicles, np.where(still, STANDING_CLEAR, SWEPT_MARGIN))
            corners = np.where(np.isfinite(corners) & (corners > 0.5), corners, np.inf).min(axis=1)
            gaps = np.minimum(gaps, corners)
            gaps = gaps[np.isfinite(gaps)]
            if len(gaps):
                stop_s = min(stop_s, float(gaps.min()) - MIN_GAP)
        if len(w.pedestrians):
            # a walking pedestrian near the path may step onto it; a standing one stops the
            # ego only inside its swept path (SUMO's pedestrians wait at a kerb for a close car)
            still = _known(self._ped_speeds, len(w.pedestrians)) < PED_MOVING
            reach = np.where(still, 0.5 * self.params.width + SWEPT_MARGIN - CORRIDOR, 0.5)
            s = self._on_path(path, w.pedestrians, reach)
            s = s[np.isfinite(s) & (s > 0.0)]
            if len(s):
                stop_s = min(stop_s, float(s.min()) - MIN_GAP)
        # traffic lights, stop signs and yielding at minor links
        for s_line, conn in path.stops:
            if self._rank(w, conn) == 1:  # a minor link: arrive slowly enough to give way
                v = min(v, math.sqrt(MINOR_ENTRY_SPEED ** 2 + 2 * COMFORT_DECEL * max(0.0, s_line)))
            key = f"{conn.from_edge}_{conn.from_lane}>{conn.via}"
            if conn.tls:
                state = w.tl_states.get(conn.tls, "")
                ch = state[conn.link_index] if 0 <= conn.link_index < len(state) else "G"
                must_stop = ch in "rRu" or (ch in "yY" and s_line > ego.speed ** 2 / (2 * 6.0))
                if must_stop:
                    stop_s = min(stop_s, s_line - STOP_MARGIN)
                continue
            if conn.state in ("s", "w") and key not in self._cleared:
                if s_line - STOP_MARGIN < 3.0 and ego.speed < 0.1:
                    since = self._stopped_at.setdefault(key, t)
                    if t - since >= STOP_SIGN_WAIT and self._junction_stop(w, conn, s_line) == math.inf:
                        self._cleared.add(key)
                        continue
                stop_s = min(stop_s, s_line - STOP_MARGIN)
        stop_s = min(stop_s, path.hold, self._yield_stop(w, path))
        if math.isfinite(stop_s):
            # the speed controller trails its target by about STOP_LAG m/s while braking
            v = min(v, max(0.0, math.sqrt(2 * COMFORT_DECEL * max(0.0, stop_s)) - STOP_LAG))
            if stop_s < 0.5:
                v = 0.0
        return max(0.0, v)

    def _signal(self, w: World, conn: Connection) -> str:
        """The link's signal now: the light's state character, else its static state
        (M major, m minor, s stop, w all-way stop)."""
        if conn.tls:
            state = w.tl_states.get(conn.tls, "")
            return state[conn.link_index] if 0 <= conn.link_index < len(state) else "G"
        return conn.state

    def _rank(self, w: World, conn: Connection) -> int:
        """Right of way of a link now: 2 major (green ``G``, ``M``, no light ``O``/``o``),
        1 minor (permissive green ``g``, ``m``), 0 stop (``s``, ``w``, red, yellow)."""
        return {"G": 2, "M": 2, "O": 2, "o": 2, "g": 1, "m": 1}.get(self._signal(w, conn), 0)

    def _yields_to(self, w: World, conn: Connection, foe: Connection) -> int:
        """How ``conn`` meets an approaching vehicle on ``foe``: 1 gives way (the foe's link
        ranks higher, :meth:`_rank`), 0 first come first served (equal rank), -1 goes first."""
        theirs, ours = self._rank(w, foe), self._rank(w, conn)
        return (theirs > ours) - (theirs < ours)

    def _yield_stop(self, w: World, path: _Path) -> float:
        """Arc position (m) before which the ego stops for junction traffic at the junctions
        within :data:`YIELD_LOOKAHEAD` m (see :meth:`_junction_stop`)."""
        return min((self._junction_stop(w, conn, s_entry) for s_entry, conn in path.junctions
                    if s_entry <= YIELD_LOOKAHEAD), default=math.inf)

    def _junction_stop(self, w: World, conn: Connection, s_entry: float) -> float:
        """Arc position (m) before which the ego stops for traffic at the junction of ``conn``,
        whose entry is ``s_entry`` m ahead (negative: the ego is inside).

        Rivals: moving vehicles whose front is inside the junction and that have not passed a
        conflict point and, where the ego gives way (:meth:`_yields_to`), moving ones
        approaching it within :data:`YIELD_APPROACH` m or :data:`YIELD_TIME` s (on a link of the
        same rank: those that get there first). A foe's arrival is estimated with
        acceleration from its speed (:data:`FOE_ACCEL`), not its speed alone: a car pulling
        away at 0.6 m/s 18 m out arrives in about 4 s, not 30. A standing car is no rival (it
        waits, often for the ego, and one on the ego's path stops the ego as an obstacle),
        except at the head of a queue on a link that ranks higher: at the start of a green it
        is about to go. The ego waits for such a car for at most :data:`STANDING_WAIT` s of
        standing still (it may be waiting for something else). Before the junction the ego
        waits at its entry while a rival would reach a conflict point before the ego has
        passed it, and a slow ego just past the entry holds there rather than creeping towards
        the conflict point into the foe's lane; at a merge it follows a rival that is no
        farther from the merge point than the ego; farther inside, it stops before the
        conflict point while it still can."""
        if len(w.vehicles) == 0:
            return math.inf
        xy, yaw, half = w.vehicles[:, :2], w.vehicles[:, 2], 0.5 * w.vehicles[:, 3]
        v_f = _known(self._speeds, len(w.vehicles))
        v_f = np.where(np.isfinite(v_f), v_f, UNSEEN_SPEED)
        moving = v_f > MOVING
        junction = junction_of(conn.via)
        since = self._queue_wait.get(junction)
        heads_count = since is None or self._now - since < STANDING_WAIT
        at_line = s_entry > 0.5 or (s_entry > -LINE_HOLD and w.ego.speed < LINE_HOLD_SPEED)
        stop = math.inf
        for cf in self._conflicts(conn):
            s_c = s_entry + cf.s_ours
            if s_c < 0.0:
                continue  # the conflict point is behind the ego
            s_v = project(cf.path, cf.cum, xy, yaw)
            d_f = cf.s_foe - s_v                       # centre's distance to the conflict point
            near = d_f < np.maximum(YIELD_APPROACH, v_f * YIELD_TIME)
            front = s_v + half                          # its front's arc position on the foe path
            ahead_of_entry = front >= cf.entry         # its front is inside the junction
            t_ego = (s_c + self.params.length + 2.0) / max(w.ego.speed, 2.0) + YIELD_MARGIN   # s until clear
            sooner = arrival_time(np.maximum(d_f, 0.0), v_f) < t_ego
            way = self._yields_to(w, conn, cf.foe)
            heads = np.zeros(len(xy), dtype=bool)
            if heads_count and way > 0 and self._rank(w, cf.foe) == 2:
                queued = np.isfinite(d_f) & ~moving & ~ahead_of_entry & (front > cf.entry - QUEUE_HEAD_M)
                if queued.any():
                    heads[np.flatnonzero(queued)[np.argmin(d_f[queued])]] = True
                    if w.ego.speed < MOVING:
                        self._queue_wait.setdefault(junction, self._now)
            rival = np.isfinite(d_f) & (d_f > -(half + 1.0)) & \
                ((moving & (ahead_of_entry | (near & (way > 0)) | (near & sooner & (way == 0)))) | heads)
            if not rival.any():
                continue
            sooner = (sooner & rival) | heads
            if cf.merge:
                ahead = rival & (d_f < s_c + MERGE_MARGIN)
                if ahead.any():
                    stop = min(stop, float((s_c - d_f[ahead] - half[ahead]).min()) - MIN_GAP)
                sooner &= ~ahead
            if not sooner.any():
                continue
            if at_line:
                stop = min(stop, s_entry - STOP_MARGIN)
            elif s_c - CONFLICT_CLEAR > w.ego.speed ** 2 / (2 * HARD_DECEL) - 0.5:
                # still able to stop short of it (or standing there already): do
                stop = min(stop, s_c - CONFLICT_CLEAR)
        return stop

    def _map(self) -> ConflictMap:
        if self._conflict_map is None or self._conflict_map.net is not self.net:
            self._conflict_map = ConflictMap(self.net)
        return self._conflict_map

    def _conflicts(self, conn: Connection) -> tuple[Conflict, ...]:
        return self._map()(conn)

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

    def __init__(self) -> None:
        super().__init__()
        # index into the route's edges of the edge the ego was last found on: a route may drive
        # one road twice (around a block and back), and each visit leaves it its own way
        self._at = 0

    def reset(self, info: EpisodeInfo) -> None:
        super().reset(info)
        self._at = 0

    def entered(self, w: World, edge: str) -> None:
        i = self._occurrence(w, edge)
        if i is not None:
            self._at = i

    def _occurrence(self, w: World, edge: str) -> int | None:
        """Index of ``edge`` on the route: its first occurrence at or after the ego's (the
        first anywhere when the ego has left the route; None if the route never drives it)."""
        edges = w.route.edges if w.route is not None else ()
        for start in (self._at, 0):
            try:
                return edges.index(edge, start)
            except ValueError:
                pass
        return None

    def choose(self, w: World, edge: str, options: list[str], tentative: bool) -> str | None:
        i = self._occurrence(w, edge)
        edges = w.route.edges if w.route is not None else ()
        return edges[i + 1] if i is not None and i + 1 < len(edges) else None


#: words that name a roundabout in an instruction
_RING_WORDS = re.compile(r"roundabout|traffic circle|rotary|\bcircle\b", re.IGNORECASE)


class InstructionFollower(PathDriver):
    """Knows the map, not the route: takes the branch the active instruction names."""

    name = "instruction-follower"

    def __init__(self) -> None:
        super().__init__()
        self.intent = Intent.FOLLOW
        self._instr_id = -1
        self._lane_done: set[int] = set()
        # the lane (edge, index) the active lane-change instruction asks for, and the one an
        # earlier unfinished lane-change instruction asked for (consecutive instructions add up)
        self._lane_goal: tuple[str, int] | None = None
        self._lane_carry: tuple[str, int] | None = None
        # the active instruction names a roundabout: at its entry the ring is taken, not a bypass
        self._ring_named = False
        self._ring_exits = 0
        # the edge at whose end the active instruction's maneuver was committed to: an
        # instruction names one junction, so the junctions after it are driven by the road
        self._spent: str | None = None

    def reset(self, info: EpisodeInfo) -> None:
        super().reset(info)
        self.intent = Intent.FOLLOW
        self._instr_id = -1
        self._lane_done = set()
        self._lane_goal = self._lane_carry = None
        self._ring_named = False
        self._ring_exits = 0
        self._spent = None

    def observe(self, obs: Observation) -> None:
        if obs.instruction_id != self._instr_id:
            unfinished = self._lane_goal is not None and self._instr_id not in self._lane_done
            self._lane_carry = self._lane_goal if unfinished else None
            self._lane_goal = None
            self._instr_id = obs.instruction_id
            self.intent = self.interpret(obs)
            self._ring_named = bool(_RING_WORDS.search(obs.instruction or ""))
            self._spent = None
            # a new instruction before a junction is entered may name another branch there:
            # the branch is chosen again (a route that starts a few metres before a junction
            # meets its turn instruction after the choice was made; inside a long junction the
            # ego has already chosen at the short edge beyond it)
            lane = obs.world.lane if obs.world is not None else ""
            if lane.startswith(":"):
                self._decided.pop(self.net.via_edges.get(lane, ("", ""))[1], None)
            elif lane:
                self._decided.pop(_lane_edge(lane), None)

    def interpret(self, obs: Observation) -> Intent:
        """The maneuver the new active instruction asks for: the ``rules`` interpreter (the
        intent classifier); :class:`icrsumo.agents.llm.LLMFollower` asks a language model."""
        return classify_intent(obs.instruction) if obs.instruction else Intent.FOLLOW

    def preferred_lane(self, w: World, edge: str, lanes: tuple[int, ...], current: int) -> int:
        if self.intent in (Intent.LANE_LEFT, Intent.LANE_RIGHT) and self._instr_id not in self._lane_done:
            step = 1 if self.intent == Intent.LANE_LEFT else -1
            if self._lane_goal is None or self._lane_goal[0] != edge:
                # one lane from where the ego is, or from where an unfinished change of the
                # same side on this edge was going
                carry = self._lane_carry
                base = carry[1] if carry is not None and carry[0] == edge and \
                    (carry[1] - current) * step > 0 else current
                self._lane_goal, self._lane_carry = (edge, base + step), None
            goal = self._lane_goal[1]
            if goal == current:
                self._lane_done.add(self._instr_id)
            elif goal in lanes:
                return goal
            elif goal in self.net.passenger_lanes.get(edge, ()):
                return current  # the lane exists but does not lead on: stay
        return super().preferred_lane(w, edge, lanes, current)

    def choose(self, w: World, edge: str, options: list[str], tentative: bool) -> str | None:
        net = self.net
        if len(options) == 1:
            return options[0]
        # a junction maneuver already committed to: the instruction is used up beyond it
        intent = self.intent if self._spent in (None, edge) else Intent.FOLLOW
        ring = net.roundabout_edges
        if self._ring_named and edge not in ring:
            # "take the n-th exit of the roundabout": the ring, not a slip road past it
            into = [o for o in options if o in ring]
            if into:
                return into[0]
        if edge in ring:
            target = {Intent.RIGHT: 1, Intent.STRAIGHT: 2, Intent.LEFT: 3}.get(intent, 2)
            exits = [o for o in options if o not in ring]
            on_ring = [o for o in options if o in ring]
            if exits and (self._ring_exits + 1 >= target or not on_ring):
                if not tentative:
                    self._ring_exits = 0
                    self._spent = edge
                return exits[0]
            if exits and not tentative:
                self._ring_exits += 1
            return on_ring[0] if on_ring else options[0]
        dirs = {o: {c.direction for c in net.connections[(edge, o)]} for o in options}
        want = {Intent.LEFT: ("l", "L"), Intent.RIGHT: ("r", "R"), Intent.STRAIGHT: ("s",)}.get(intent)
        if want:
            for d in want:
                for o in options:
                    if d in dirs[o]:
                        if not tentative and not any(n in ring for n in (o, *options)):
                            self._spent = edge
                        return o
        for d in ("s", "L", "R", "r", "l"):
            for o in options:
                if d in dirs[o]:
                    return o
        return options[0]
