"""Trajectories as the reports draw them: where a variant diverged from its baseline, and a
logged trajectory thinned for drawing."""

from __future__ import annotations

import numpy as np

from icrsumo.core.types import EpisodeLog

#: m: a variant has diverged where its ego is this far from the baseline's at the same time
DIVERGED_M = 3.0
#: m: a drawn trajectory keeps the points that are more than this off its simplified line
SIMPLIFY_M = 0.3
#: at most this many points of a trajectory are drawn (evenly spaced along it)
MAX_POINTS = 300


def divergence_t(base: EpisodeLog, var: EpisodeLog) -> float | None:
    """The first time (s) the variant's ego is :data:`DIVERGED_M` or more from the baseline's
    at the same simulation time (None: never within the shorter log)."""
    n = min(len(base.t), len(var.t))
    if n == 0:
        return None
    bx, by = np.asarray(base.x[:n]), np.asarray(base.y[:n])
    d = np.hypot(bx - np.asarray(var.x[:n]), by - np.asarray(var.y[:n]))
    idx = np.flatnonzero(d >= DIVERGED_M)
    return float(var.t[idx[0]]) if len(idx) else None


def simplify(xy: np.ndarray, tol: float = SIMPLIFY_M) -> np.ndarray:
    """(M, 2) m: the polyline ``xy`` with the points that lie within ``tol`` m of the line
    between their kept neighbours dropped (Ramer-Douglas-Peucker; the ends are kept)."""
    n = len(xy)
    if n < 3:
        return xy
    keep = np.zeros(n, dtype=bool)
    keep[[0, n - 1]] = True
    stack = [(0, n - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        seg = xy[b] - xy[a]
        rel = xy[a + 1:b] - xy[a]
        length = float(np.hypot(*seg))
        if length > 0:
            dist = np.abs(seg[0] * rel[:, 1] - seg[1] * rel[:, 0]) / length
        else:
            dist = np.hypot(rel[:, 0], rel[:, 1])
        i = int(np.argmax(dist))
        if dist[i] > tol:
            keep[a + 1 + i] = True
            stack += [(a, a + 1 + i), (a + 1 + i, b)]
    return xy[keep]


def drawn_points(log: EpisodeLog) -> np.ndarray:
    """(M, 2) m: the trajectory, simplified to :data:`SIMPLIFY_M` (at most :data:`MAX_POINTS`
    points, the last one kept)."""
    xy = simplify(np.column_stack([log.x, log.y])) if log.t else np.zeros((0, 2))
    if len(xy) > MAX_POINTS:
        idx = np.unique(np.append(np.linspace(0, len(xy) - 1, MAX_POINTS).round().astype(int), len(xy) - 1))
        xy = xy[idx]
    return xy
