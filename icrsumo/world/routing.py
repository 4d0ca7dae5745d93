"""Waypoints -> ego route: map matching of leaderboard waypoints to lanes and the shortest
path through them (as the leaderboard's route planner does), then the lane-level route:
centre polyline, junctions passed, lane changes required.

All positions are SUMO coordinates in metres; headings in radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from icrsumo.core.angles import angle_diff
from icrsumo.core.types import EgoRoute, JunctionPass, LaneChange, LanePos

from .networks import RoadNet

#: a heading mismatch of 180 degrees costs 2x this many metres of snapping distance. Small on
#: purpose: the leaderboard's planner ignores yaw and real LangAuto files carry coarse or wrong
#: yaws (destinations often say 0.0), so yaw only breaks ties between equally near lanes.
HEADING_WEIGHT_M = 1.0
#: metres of snapping distance that one metre of route length costs: a tie-breaker only, so that
#: each waypoint keeps its nearest lane (the leaderboard localises waypoints on the nearest
#: driving lane and plans the shortest path between them) unless no path leaves from there
PATH_WEIGHT = 1e-3
#: candidate edges kept per waypoint
MAX_CANDIDATES = 6
#: on the same edge, a waypoint this far (m) behind the previous one still counts as ahead
SAME_EDGE_SLACK_M = 0.5


class MatchError(Exception):
    """Matching failed at waypoint ``index``; ``kind`` is 'far' or 'nopath'."""

    def __init__(self, kind: str, index: int, detail: str) -> None:
        super().__init__(detail)
        self.kind, self.index, self.detail = kind, index, detail


@dataclass(frozen=True)
class _Cand:
    edge: str
    lane: str
    pos: float
    cost: float


def candidates(
    net: RoadNet, x: float, y: float, heading: float | None, radius: float
) -> list[_Cand]:
    """Lane positions a waypoint may stand for, cheapest first (cost in m).

    A point inside a junction stands for the end of the connection's incoming edge or the start
    of its outgoing edge.
    """
    best: dict[str, _Cand] = {}
    for lane, pos, dist, lane_heading in net.project(x, y, radius):
        cost = dist
        if heading is not None:
            cost += HEADING_WEIGHT_M * (1.0 - math.cos(angle_diff(heading, lane_heading)))
        edge = lane.rsplit("_", 1)[0]
        if lane.startswith(":"):
            if lane not in net.via_edges:
                continue
            src, dst = net.via_edges[lane]
            src_lane = f"{src}_{net.connections[(src, dst)][0].from_lane}"
            dst_lane = f"{dst}_{net.connections[(src, dst)][0].to_lane}"
            opts = [_Cand(src, src_lane, net.edge_length[src], cost),
                    _Cand(dst, dst_lane, 0.0, cost)]
        elif edge in net.passenger_lanes:
            opts = [_Cand(edge, lane, min(pos, net.edge_length[edge]), cost)]
        else:
            continue
        for c in opts:
            old = best.get(c.edge)
            if old is None or (c.cost, c.lane) < (old.cost, old.lane):
                best[c.edge] = c
    ranked = sorted(best.values(), key=lambda c: (c.cost, c.edge))
    return ranked[:MAX_CANDIDATES]


def _transitions(net: RoadNet, a: _Cand, targets: list[_Cand]):
    """Route distance (m) and intermediate edges from ``a`` to each target candidate."""
    out: list[tuple[float, tuple[str, ...]] | None] = [None] * len(targets)
    need = set()
    for j, b in enumerate(targets):
        if b.edge == a.edge and b.pos >= a.pos - SAME_EDGE_SLACK_M:
            out[j] = (max(0.0, b.pos - a.pos), ())
        else:
            need.add(b.edge)
    if need:
        paths = net.shortest_paths(a.edge, a.pos, need)
        for j, b in enumerate(targets):
            if out[j] is None and b.edge in paths:
                d, mid = paths[b.edge]
                out[j] = (d + b.pos, mid)
    return out


def match_waypoints(
    net: RoadNet, points: list[tuple[float, float, float | None]], radius: float
) -> tuple[list[str], _Cand, _Cand]:
    """Map-match waypoints (x, y, heading or None) and plan the shortest path through them.

    Like the CARLA leaderboard's planner, each waypoint is localised on its nearest lane and
    consecutive waypoints are joined by the shortest path. Done as a Viterbi pass over
    per-waypoint lane candidates (cost = snapping distance + heading tie-breaker + PATH_WEIGHT x
    route distance), so that a waypoint falls back to a farther lane only when no path leaves
    its nearest one. Returns the edge list and the matched start and end candidates.
    Raises MatchError.
    """
    cands = []
    for i, (x, y, h) in enumerate(points):
        c = candidates(net, x, y, h, radius)
        if not c:
            raise MatchError("far", i, f"no drivable lane within {radius:g} m of ({x:.2f}, {y:.2f})")
        cands.append(c)
    cost = [c.cost for c in cands[0]]
    back: list[list[tuple[int, tuple[str, ...]]]] = []
    for i in range(1, len(points)):
        new_cost = [math.inf] * len(cands[i])
        new_back: list[tuple[int, tuple[str, ...]]] = [(-1, ())] * len(cands[i])
        for k, a in enumerate(cands[i - 1]):
            if not math.isfinite(cost[k]):
                continue
            for j, tr in enumerate(_transitions(net, a, cands[i])):
                if tr is None:
                    continue
                total = cost[k] + PATH_WEIGHT * tr[0] + cands[i][j].cost
                if total < new_cost[j] - 1e-9:
                    new_cost[j] = total
                    new_back[j] = (k, tr[1])
        if not any(math.isfinite(c) for c in new_cost):
            raise MatchError("nopath", i, f"no drivable path from waypoint {i - 1} to waypoint {i}")
        cost = new_cost
        back.append(new_back)
    j = min(range(len(cost)), key=lambda m: (cost[m], m))
    end = cands[-1][j]
    chain: list[tuple[int, tuple[str, ...]]] = []
    for i in range(len(points) - 1, 0, -1):
        k, mid = back[i - 1][j]
        chain.append((j, mid))
        j = k
    start = cands[0][j]
    edges = [start.edge]
    cur = start
    for i, (jj, mid) in enumerate(reversed(chain), start=1):
        nxt = cands[i][jj]
        if mid or nxt.edge != cur.edge or nxt.pos < cur.pos - SAME_EDGE_SLACK_M:
            edges.extend(mid)
            edges.append(nxt.edge)
        cur = nxt
    return edges, start, end


def _choose_connection(net: RoadNet, a: str, b: str, lane: int):
    """The connection from edge a to b closest to the current lane index (fewest changes)."""
    conns = net.connections[(a, b)]
    return min(conns, key=lambda c: (abs(c.from_lane - lane), c.from_lane,
                                     abs(c.to_lane - c.from_lane), c.to_lane))


def build_route(net: RoadNet, edges: list[str], start: _Cand, end: _Cand) -> EgoRoute:
    """Lane-level route through ``edges`` from ``start`` to ``end``: the lanes driven, the
    junctions crossed, the lane changes required and the centre polyline."""
    n = len(edges)
    cur = int(start.lane.rsplit("_", 1)[1])
    lane_path: list[int] = []
    route_lanes: list[tuple[int, ...]] = []
    junctions: list[JunctionPass] = []
    changes: list[LaneChange] = []
    pieces: list[np.ndarray] = []
    heads: list[list[float]] = []
    length = 0.0

    def add(piece: np.ndarray) -> None:
        nonlocal length
        h = lane_headings(piece, heads[-1][-1] if heads else 0.0)
        if pieces and len(piece) and _close(pieces[-1][-1], piece[0]):
            piece, h = piece[1:], h[1:]
        if len(piece):
            if pieces:
                length += float(np.hypot(*(piece[0] - pieces[-1][-1])))
            length += float(np.hypot(*np.diff(piece, axis=0).T).sum()) if len(piece) > 1 else 0.0
            pieces.append(piece)
            heads.append(h)

    for i, edge in enumerate(edges):
        a_pos = start.pos if i == 0 else 0.0
        if i == n - 1:
            b_pos = end.pos
            route_lanes.append(net.passenger_lanes[edge])
            lane = cur if cur in net.passenger_lanes[edge] else int(end.lane.rsplit("_", 1)[1])
            lane_path.append(lane)
            add(net.lane_slice(f"{edge}_{lane}", a_pos, b_pos))
            break
        nxt = edges[i + 1]
        conn = _choose_connection(net, edge, nxt, cur)
        route_lanes.append(tuple(sorted({c.from_lane for c in net.connections[(edge, nxt)]})))
        if conn.from_lane != cur:
            changes.append(LaneChange(edge, round(length, 2), cur, conn.from_lane))
        lane_path.append(conn.from_lane)
        add(net.lane_slice(f"{edge}_{conn.from_lane}", a_pos, net.edge_length[edge]))
        node = net.edge_to_node[edge]
        junctions.append(JunctionPass(
            junction=node, junction_type=net.node_type.get(node, ""), from_edge=edge,
            to_edge=nxt, from_lane=conn.from_lane, to_lane=conn.to_lane, via=conn.via,
            direction=conn.direction,
            choice=net.offers_choice(edge),
            roundabout=edge in net.roundabout_edges or nxt in net.roundabout_edges,
            pos=round(length, 2),
        ))
        for via in conn.via_chain:
            add(net.lane_shape[via])
        cur = conn.to_lane
    poly = np.vstack(pieces) if pieces else np.zeros((0, 2))
    sx, sy, sh = net.lane_pose(start.lane, start.pos)
    ex, ey, eh = net.lane_pose(end.lane, end.pos)
    return EgoRoute(
        edges=tuple(edges),
        lanes=tuple(route_lanes),
        lane_path=tuple(lane_path),
        start=LanePos(start.lane, round(start.pos, 2), round(sx, 2), round(sy, 2), round(sh, 4)),
        end=LanePos(end.lane, round(end.pos, 2), round(ex, 2), round(ey, 2), round(eh, 4)),
        polyline=tuple((round(float(x), 2), round(float(y), 2)) for x, y in poly),
        length=round(length, 2),
        junctions=tuple(junctions),
        lane_changes=tuple(changes),
        headings=tuple(round(h, 4) + 0.0 for hs in heads for h in hs),
    )


def _close(a: np.ndarray, b: np.ndarray) -> bool:
    """``np.allclose(a, b)`` for two points (2,) m, without numpy's per-call overhead."""
    return (abs(float(a[0]) - float(b[0])) <= 1e-8 + 1e-5 * abs(float(b[0]))
            and abs(float(a[1]) - float(b[1])) <= 1e-8 + 1e-5 * abs(float(b[1])))


def lane_headings(shape: np.ndarray, before: float) -> list[float]:
    """The direction (rad) of a lane piece ((N, 2) m) at each vertex: of the segment starting
    there, the last vertex that of the segment ending there; a zero-length segment takes its
    neighbour's, a single point ``before``."""
    n = len(shape)
    pts = np.asarray(shape, dtype=float).tolist()
    segs = []
    for (x0, y0), (x1, y1) in zip(pts[:-1], pts[1:]):
        dx, dy = x1 - x0, y1 - y0
        segs.append(math.atan2(dy, dx) if float(np.hypot(dx, dy)) > 1e-9 else None)
    known = [h for h in segs if h is not None]
    if not known:
        return [before] * n
    out, last = [], known[0]
    for h in segs:
        last = h if h is not None else last
        out.append(last)
    return out + [last]


def plan_route(
    net: RoadNet, points: list[tuple[float, float, float | None]], radius: float
) -> EgoRoute:
    """Waypoints in SUMO coordinates -> the ego's lane-level route. Raises MatchError."""
    edges, start, end = match_waypoints(net, points, radius)
    return build_route(net, edges, start, end)
