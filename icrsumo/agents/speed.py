"""How fast the privileged agents drive (:class:`~icrsumo.agents.driver.PathDriver`): the speed
along the lane path they planned, from the speed limit, curvature, the gap to vehicles and
pedestrians on the path, traffic-light states and stop signs, and giving way at junctions to
the vehicles that have the right of way (junction foes from :mod:`icrsumo.agents.conflicts`).
Other vehicles' and pedestrians' speeds are estimated from their positions at the previous
call: the agents get no ids."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from icrsumo.world.dynamics import VehicleParams
from icrsumo.world.networks import Connection, RoadNet

from .base import World
from .conflicts import Conflict, ConflictMap, junction_of, project

COMFORT_DECEL = 3.0      # m/s^2 used to plan stops
HARD_DECEL = 6.0         # m/s^2 the ego can brake with when it must (a conflict point inside a junction)
STOP_LAG = 1.0           # m/s the planned stopping speed is lowered by (the PI controller trails it)
LAT_ACCEL = 2.0          # m/s^2 allowed in curves
MIN_GAP = 4.0            # m kept to the vehicle or pedestrian ahead (bumper to bumper)
STOP_MARGIN = 1.0        # m before a stop line (front bumper)
CORRIDOR = 2.0           # m lateral half-width in which an object is "on the path"
STOP_SIGN_WAIT = 1.0     # s stopped at a stop sign before going on
CRUISE_FACTOR = 0.9      # fraction of the speed limit driven
YIELD_LOOKAHEAD = 60.0   # m ahead within which junction entries are checked for traffic to yield to
YIELD_APPROACH = 35.0    # m from a conflict point within which a vehicle with the right of way is waited for
CONFLICT_CLEAR = 3.0     # m before a conflict point where the ego's front stops
MERGE_MARGIN = 3.0       # m: a vehicle this much farther from a merge than the ego still goes first
MOVING = 0.5             # m/s above which another vehicle counts as moving
YIELD_TIME = 4.0         # s from a conflict point within which a vehicle with the right of way is waited for
UNSEEN_SPEED = 15.0      # m/s assumed for a vehicle not seen at the previous call
MINOR_ENTRY_SPEED = 6.0  # m/s at most when entering a junction on a minor link (g, m)
YIELD_MARGIN = 2.0       # s the ego keeps between clearing a conflict point and a rival reaching it
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


def known_speeds(speeds: np.ndarray, n: int) -> np.ndarray:
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
class PlannedPath:
    """The lane path ahead of the ego, as the driver planned it and the speed policy reads it."""

    points: np.ndarray                       # (N, 2) m
    cum: np.ndarray                          # (N,) arc length m
    speed: np.ndarray                        # (N,) speed limit m/s
    stops: list[tuple[float, Connection]] = field(default_factory=list)   # (s of stop line, conn)
    hold: float = math.inf                   # s (m) where the ego must stop: no way on from its lane yet
    junctions: list[tuple[float, Connection]] = field(default_factory=list)  # (s of junction entry, conn)


class SpeedPolicy:
    """The target speed along a :class:`PlannedPath` (:meth:`_target_speed`), for
    :class:`~icrsumo.agents.driver.PathDriver`, which holds the state read here: the network,
    the ego's size, others' estimated speeds (:meth:`_track`) and what the ego has waited for
    at stop signs and junctions."""

    net: RoadNet | None
    params: VehicleParams
    _stopped_at: dict[str, float]
    _cleared: set[str]
    _conflict_map: ConflictMap | None
    _seen: tuple[float, np.ndarray] | None
    _speeds: np.ndarray
    _ped_seen: tuple[float, np.ndarray] | None
    _ped_speeds: np.ndarray
    _queue_wait: dict[str, float]
    _now: float

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

    # ----------------------------------------------------------------- speed
    def _on_path(self, path: PlannedPath, xy: np.ndarray, half: np.ndarray | float) -> np.ndarray:
        """Arc position (m) of each object centre projected on the path, NaN off the corridor."""
        if len(xy) == 0:
            return np.zeros(0)
        return project(path.points, path.cum, xy, corridor=CORRIDOR + half)

    def _corners_on_path(self, path: PlannedPath, vehicles: np.ndarray, margin: np.ndarray) -> np.ndarray:
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

    def _target_speed(self, w: World, path: PlannedPath, t: float) -> float:
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
            v_f = known_speeds(self._speeds, len(w.vehicles))
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
            still = known_speeds(self._ped_speeds, len(w.pedestrians)) < PED_MOVING
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

    def _yield_stop(self, w: World, path: PlannedPath) -> float:
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
        v_f = known_speeds(self._speeds, len(w.vehicles))
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
