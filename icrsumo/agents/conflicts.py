"""Where a connection's path through a junction meets the paths of other connections, from the
network's geometry alone (used by the privileged agents to yield).

SUMO's background vehicles do not yield to the ego: it is moved with ``moveToXY``, so it never
announces its approach to a junction link, and a car on a minor link drives as if the ego were
not coming. The privileged agents therefore look for junction foes themselves: every
connection of the same junction from another incoming edge whose internal lanes cross its own
(centre lines within :data:`CONFLICT_M`), or that ends on the same lane (a merge).
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass

import numpy as np
from shapely.geometry import LineString
from shapely.ops import nearest_points

from icrsumo.world.networks import Connection, RoadNet, polyline_cumlen

#: m between two internal lanes' centre lines below which they conflict (two car widths)
CONFLICT_M = 2.0
#: m between two merging lanes' centre lines below which two cars on them touch (widths + margin)
MERGE_M = 3.0
#: m between the points at which a merge's lanes are tested for where they first meet
MERGE_STEP = 0.5
#: m of a foe's incoming lane, before the junction, over which its vehicles are watched
APPROACH_M = 70.0


@dataclass(frozen=True)
class Conflict:
    """One foe connection of ``conn``: the point where their paths meet, at ``s_ours`` m along
    ``conn``'s internal lanes and ``s_foe`` m along ``path`` ((N, 2) m: the last
    :data:`APPROACH_M` of the foe's incoming lane, then its internal lanes; ``cum`` (N,) m its
    arc length, ``entry`` m where the junction begins on it). ``merge``: both end on one lane."""

    foe: Connection
    merge: bool
    s_ours: float
    s_foe: float
    path: np.ndarray
    cum: np.ndarray
    entry: float


def junction_of(lane: str) -> str:
    """The junction id of an internal lane ``:J_link_index``."""
    return lane[1:].rsplit("_", 2)[0]


def _chain(net: RoadNet, conn: Connection) -> np.ndarray:
    parts = [net.lane_shape[v] for v in conn.via_chain]
    return np.concatenate(parts) if parts else np.zeros((0, 2))


class ConflictMap:
    """The conflicts of every connection of one network, computed on first use."""

    def __init__(self, net: RoadNet) -> None:
        self.net = net
        self._by_junction: dict[str, list[Connection]] | None = None
        self._cache: dict[tuple[str, str, int], tuple[Conflict, ...]] = {}
        self._into: dict[tuple[str, int], list[Connection]] | None = None
        self._approach: dict[str, tuple[tuple[np.ndarray, np.ndarray, float], ...]] = {}

    def _junctions(self) -> dict[str, list[Connection]]:
        if self._by_junction is None:
            index: dict[str, list[Connection]] = defaultdict(list)
            for conns in self.net.connections.values():
                for c in conns:
                    if c.via:
                        index[junction_of(c.via)].append(c)
            self._by_junction = dict(index)
        return self._by_junction

    def approaches(self, lane: str) -> tuple[tuple[np.ndarray, np.ndarray, float], ...]:
        """The ways into ``lane``: per connection that leads into it, the connection's
        internal lanes and then the lane's own shape, as (polyline (M, 2) m, its arc length (M,)
        m, arc length at which ``lane`` begins, m); the lane's shape alone (offset 0) when nothing
        leads into it. A car coming up behind the ego near the start of a short lane is still on
        one of those. The incoming lanes before them are left out: a car there may be bound for
        another connection."""
        if lane not in self._approach:
            net = self.net
            if self._into is None:
                into: dict[tuple[str, int], list[Connection]] = defaultdict(list)
                for conns in net.connections.values():
                    for c in conns:
                        into[(c.to_edge, c.to_lane)].append(c)
                self._into = dict(into)
            own = net.lane_shape[lane]
            own_len = float(polyline_cumlen(own)[-1])
            edge, index = lane.rsplit("_", 1)
            found = []
            for c in self._into.get((edge, int(index)), ()):
                path = np.concatenate([_chain(net, c), own])
                path = path[np.concatenate([[True], np.hypot(*np.diff(path, axis=0).T) > 1e-3])]
                cum = polyline_cumlen(path)
                found.append((path, cum, float(cum[-1]) - own_len))
            self._approach[lane] = tuple(found) or ((own, polyline_cumlen(own), 0.0),)
        return self._approach[lane]

    def __call__(self, conn: Connection) -> tuple[Conflict, ...]:
        key = (conn.via, conn.to_edge, conn.to_lane)
        if key not in self._cache:
            self._cache[key] = self._compute(conn)
        return self._cache[key]

    def _compute(self, conn: Connection) -> tuple[Conflict, ...]:
        net = self.net
        ours = _chain(net, conn)
        if not conn.via or len(ours) < 2:
            return ()
        line = LineString(ours)
        found = []
        for foe in self._junctions().get(junction_of(conn.via), ()):
            if foe.from_edge == conn.from_edge:
                continue
            theirs = _chain(net, foe)
            if len(theirs) < 2:
                continue
            foe_line = LineString(theirs)
            merge = (foe.to_edge, foe.to_lane) == (conn.to_edge, conn.to_lane)
            if merge:
                # two lanes that end on one lane converge over metres: they meet where they
                # first come within MERGE_M (two cars side by side), not at their common end
                s_ours, s_foe_via = line.length, foe_line.length
                for s_at in np.arange(0.0, line.length, MERGE_STEP):
                    point = line.interpolate(s_at)
                    if point.distance(foe_line) < MERGE_M:
                        s_ours, s_foe_via = float(s_at), foe_line.project(point)
                        break
            elif line.distance(foe_line) < CONFLICT_M:
                p_ours, p_foe = nearest_points(line, foe_line)
                s_ours, s_foe_via = line.project(p_ours), foe_line.project(p_foe)
            else:
                continue
            lane = f"{foe.from_edge}_{foe.from_lane}"
            length = net.lane_length[lane]
            tail = net.lane_slice(lane, max(0.0, length - APPROACH_M), length)
            path = np.concatenate([tail, theirs])
            keep = np.concatenate([[True], np.hypot(*np.diff(path, axis=0).T) > 1e-3])
            path = path[keep]
            entry = float(polyline_cumlen(tail)[-1]) if len(tail) > 1 else 0.0
            found.append(Conflict(foe=foe, merge=merge, s_ours=float(s_ours), s_foe=entry + float(s_foe_via),
                                  path=path, cum=polyline_cumlen(path), entry=entry))
        return tuple(found)


def project(points: np.ndarray, cum: np.ndarray, xy: np.ndarray, yaw: np.ndarray | None = None,
            corridor: float | np.ndarray = 1.5) -> np.ndarray:
    """Arc position (m) along the polyline ``points`` ((S+1, 2) m, arc length ``cum``) of each
    point of ``xy`` ((N, 2) m) projected on its nearest segment; NaN where it lies farther than
    ``corridor`` m from the line or, given ``yaw`` ((N,) rad), heads more than 60 degrees off
    the segment's direction."""
    if len(xy) == 0 or len(points) < 2:
        return np.full(len(xy), np.nan)
    a, ab = points[:-1], np.diff(points, axis=0)
    seg = np.maximum((ab ** 2).sum(axis=1), 1e-9)
    rel = xy[:, None, :] - a[None, :, :]
    u = np.clip((rel * ab[None]).sum(axis=2) / seg[None], 0.0, 1.0)
    d = np.hypot(rel[..., 0] - u * ab[None, :, 0], rel[..., 1] - u * ab[None, :, 1])
    k = d.argmin(axis=1)
    rows = np.arange(len(xy))
    s = cum[k] + u[rows, k] * np.sqrt(seg[k])
    near = d[rows, k] < corridor
    if yaw is not None:
        heading = np.arctan2(ab[k, 1], ab[k, 0])
        near &= np.abs((yaw - heading + np.pi) % (2 * np.pi) - np.pi) < np.pi / 3
    return np.where(near, s, np.nan)
