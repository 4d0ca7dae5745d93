"""The route as the leaderboard's criteria see it (:class:`DenseRoute`): the route polyline
interpolated at a 1 m hop (``interpolate_trajectory(..., hop_resolution=1.0)`` of the
leaderboard's ``leaderboard/utils/route_manipulation.py``), each point with its lane's
direction, distances between consecutive points as straight lines. Pure geometry, no SUMO:
the closed loop (:mod:`icrsumo.sim.episode`) builds it from the scenario, the replay of a
stored log (:func:`dense_route`) from the log's polyline.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from icrsumo.core.angles import angle_diff
from icrsumo.core.types import EpisodeLog

#: hop (m) of the dense route (leaderboard: ``interpolate_trajectory(hop_resolution=1.0)``)
HOP_M = 1.0


@dataclass(frozen=True)
class DenseRoute:
    """The route as the leaderboard's criteria see it: points (m) every :data:`HOP_M` m of arc
    along the route polyline and its last point, the unit direction of the route at each
    point, and ``accum`` (m): straight-line distance summed from the first point (so
    ``accum[-1]`` is the route length the criteria use)."""

    x: tuple[float, ...]
    y: tuple[float, ...]
    fx: tuple[float, ...]
    fy: tuple[float, ...]
    accum: tuple[float, ...]

    @classmethod
    def from_polyline(cls, polyline: Sequence[Sequence[float]]) -> DenseRoute:
        """The dense route of a polyline ((N, 2) m, or (N, 3) with the lane's heading in rad at
        each vertex; N >= 1; repeated points are skipped).

        Without headings the polyline is one lane: points every :data:`HOP_M` m of arc, each
        with its segment's direction. With headings, a point's direction is its lane's, as
        CARLA takes it from the lane under the route point, and the polyline is cut into lane
        pieces at the segments that join two lanes (a segment more than
        :data:`JOIN_RAD` off the heading of its first vertex: a lane change's sideways step, a
        junction lane that starts off the end of the lane before it). Each piece is sampled on
        its own. A join between lanes of about the same heading that moves at most
        :data:`LANE_CHANGE_FORWARD_M` forward (a lane change) is one step from the last point of
        a piece to the first of the next, as the leaderboard's route has one waypoint on each
        lane; a longer one (a gap in the road's shape) is sampled along its line; a join between
        lanes more than :data:`TURN_JOIN_RAD` apart (a
        junction whose lane shape does not meet the lanes) becomes a straight cut from
        :data:`TURN_CUT_M` m before the end of the lane it leaves, sampled in its own direction.
        Points that double back along the road just driven are dropped
        (:func:`_drop_overlaps`)."""
        pts: list[tuple[float, float]] = []
        heads: list[float | None] = []
        for p in polyline:
            q = (float(p[0]), float(p[1]))
            h = float(p[2]) if len(p) > 2 else None
            if not all(math.isfinite(v) for v in (*q, 0.0 if h is None else h)):
                raise ValueError(f"route point {p!r} is not finite")
            if not pts or q != pts[-1]:
                pts.append(q)
                heads.append(h)
        if not pts:
            raise ValueError("the route has no points")
        samples: list[tuple[float, float, float, float]] = []
        for piece in _lane_pieces(pts, heads):
            for p in _sample(piece):
                if not samples or p[:2] != samples[-1][:2]:
                    samples.append(p)
        if all(h is not None for h in heads):
            samples = _drop_overlaps(samples)
        xs, ys, fxs, fys = (list(c) for c in zip(*samples))
        accum = [0.0]
        for i in range(1, len(xs)):
            accum.append(accum[-1] + math.hypot(xs[i] - xs[i - 1], ys[i] - ys[i - 1]))
        return cls(tuple(xs), tuple(ys), tuple(fxs), tuple(fys), tuple(accum))

    @property
    def length(self) -> float:
        """Route length (m) as the criteria measure it: ``accum[-1]``."""
        return self.accum[-1]

    def passed(self, i: int, x: float, y: float) -> bool:
        """Whether (x, y) is ahead of point ``i`` along the route's direction there (dot > 0)."""
        return (x - self.x[i]) * self.fx[i] + (y - self.y[i]) * self.fy[i] > 0.0


#: a segment more than this far off its first vertex's lane heading joins two lanes (rad)
JOIN_RAD = math.radians(10.0)
#: lanes whose headings differ by more than this (rad) are joined by a turn, which a straight
#: cut stands for (a junction whose lane shape does not meet the lanes), starting this far (m)
#: before the end of the lane it leaves, as a driver turns in before the corner
TURN_JOIN_RAD = math.radians(45.0)
TURN_CUT_M = 5.0
#: a join between lanes of about the same heading that moves at most this far (m) forward is a
#: lane change's sideways step (one step); a longer one is a gap in the road's shape, sampled
LANE_CHANGE_FORWARD_M = 2.0
#: a dense point doubling back less than this far (m) behind the last one kept ...
OVERLAP_BACK_M = 20.0
#: ... and less than this far (m) beside its line is dropped (:func:`_drop_overlaps`)
OVERLAP_SIDE_M = 2.0

_Piece = list[tuple[float, float, float | None]]


def _lane_pieces(pts: list[tuple[float, float]], heads: list[float | None]) -> list[_Piece]:
    """The polyline cut into lane pieces at its joins (see :meth:`DenseRoute.from_polyline`):
    lists of (x, y, heading or None)."""
    if any(h is None for h in heads):
        return [[(x, y, None) for x, y in pts]]
    pieces: list[_Piece] = [[(pts[0][0], pts[0][1], heads[0])]]
    for i in range(1, len(pts)):
        (ax, ay), (bx, by), h = pts[i - 1], pts[i], heads[i - 1]
        d = math.atan2(by - ay, bx - ax)
        if angle_diff(d, h) > JOIN_RAD:
            forward = (bx - ax) * math.cos(h) + (by - ay) * math.sin(h)
            if angle_diff(heads[i], h) > TURN_JOIN_RAD:  # a turn with no lane shape: a straight cut
                a = _cut_tail(pieces[-1], TURN_CUT_M) if len(pieces[-1]) > 1 else pieces[-1][-1]
                d = math.atan2(by - a[1], bx - a[0])
                pieces.append([(a[0], a[1], d), (bx, by, d)])
            elif forward > LANE_CHANGE_FORWARD_M:  # a gap along the road: driven straight on
                pieces.append([(ax, ay, d), (bx, by, d)])
            pieces.append([])
        pieces[-1].append((bx, by, heads[i]))
    return pieces


def _cut_tail(piece: _Piece, length: float) -> tuple[float, float, float | None]:
    """Shorten ``piece`` (in place) by ``length`` m of arc, keeping its first point; its new
    last point."""
    left = length
    while len(piece) > 1:
        (ax, ay, h), (bx, by, _) = piece[-2], piece[-1]
        seg = math.hypot(bx - ax, by - ay)
        if seg > left:
            u = 1.0 - left / seg
            piece[-1] = (ax + (bx - ax) * u, ay + (by - ay) * u, h)
            break
        left -= seg
        piece.pop()
    return piece[-1]


_Point = tuple[float, float, float, float]


def _drop_overlaps(points: list[_Point]) -> list[_Point]:
    """The dense points without those that double back along the road just driven: a point
    less than :data:`OVERLAP_BACK_M` behind the last point kept (along its direction) and less
    than :data:`OVERLAP_SIDE_M` beside that line (a junction lane that starts behind the end of
    the lane before it). A later visit of the same road is farther back and stays."""
    kept: list[_Point] = []
    for p in points:
        if kept:
            kx, ky, fx, fy = kept[-1]
            dx, dy = p[0] - kx, p[1] - ky
            along, side = dx * fx + dy * fy, abs(dx * fy - dy * fx)
            if -OVERLAP_BACK_M < along < 0.0 and side < OVERLAP_SIDE_M:
                continue
        kept.append(p)
    return kept


def _sample(piece: _Piece) -> list[tuple[float, float, float, float]]:
    """Points of one lane piece every :data:`HOP_M` m of arc from its start, and its end:
    (x, y, direction x, direction y)."""
    if len(piece) == 1:
        x, y, h = piece[0]
        return [(x, y, math.cos(h), math.sin(h)) if h is not None else (x, y, 1.0, 0.0)]
    segs = []
    for (ax, ay, h), (bx, by, _) in zip(piece, piece[1:]):
        ln = math.hypot(bx - ax, by - ay)
        fx, fy = (math.cos(h), math.sin(h)) if h is not None else ((bx - ax) / ln, (by - ay) / ln)
        segs.append((ax, ay, bx, by, ln, fx, fy))
    total = math.fsum(sg[4] for sg in segs)
    n_hops = int(math.floor(total / HOP_M + 1e-9))
    targets = [k * HOP_M for k in range(n_hops + 1)]
    if total - targets[-1] > 1e-6:
        targets.append(total)
    out = []
    k, start = 0, 0.0
    for s in targets:
        while k < len(segs) - 1 and start + segs[k][4] <= s:
            start += segs[k][4]
            k += 1
        ax, ay, bx, by, ln, fx, fy = segs[k]
        u = min(max((s - start) / ln, 0.0), 1.0)
        out.append((ax + (bx - ax) * u, ay + (by - ay) * u, fx, fy))
    return out


def dense_route(log: EpisodeLog) -> DenseRoute:
    """The dense route of the log's route polyline and headings (ValueError when the log has
    none)."""
    if not log.route:
        raise ValueError("the episode log holds no route polyline")
    return DenseRoute.from_polyline(log.route)
