"""Expert labels: the route-oracle's planned path resampled at fixed arc lengths.

A label is ``(K, 2)`` points (m, ego frame: x forward, y left) at the arc lengths
:data:`ARC_M` along the expert's planned path, plus the expert's target speed (m/s). The
learned agents predict the same and hand both to the built-in waypoint controller.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: arc lengths (m) along the planned path at which the label points lie
ARC_M = np.array([2.5, 5.0, 7.5, 10.0, 12.5, 15.0, 17.5, 20.0])
#: target speeds (m/s) below this count as "stop"
STOP_BELOW = 0.3


def resample_path(waypoints: np.ndarray, arc: np.ndarray = ARC_M) -> np.ndarray:
    """Points at arc lengths ``arc`` (m) along the polyline origin -> ``waypoints`` ((N, 2) m,
    ego frame), extended straight past its end; returns ``(len(arc), 2)`` float32."""
    pts = np.vstack([[0.0, 0.0], np.asarray(waypoints, dtype=float).reshape(-1, 2)])
    seg = np.hypot(*np.diff(pts, axis=0).T)
    keep = np.concatenate([[True], seg > 1e-6])
    pts = pts[keep]
    if len(pts) < 2:
        out = np.zeros((len(arc), 2))
        out[:, 0] = arc
        return out.astype(np.float32)
    seg = np.hypot(*np.diff(pts, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    x = np.interp(arc, cum, pts[:, 0])
    y = np.interp(arc, cum, pts[:, 1])
    beyond = arc > cum[-1]
    if beyond.any():
        d = (pts[-1] - pts[-2]) / seg[-1]
        extra = arc[beyond] - cum[-1]
        x[beyond] = pts[-1, 0] + d[0] * extra
        y[beyond] = pts[-1, 1] + d[1] * extra
    return np.stack([x, y], axis=1).astype(np.float32)


#: the ego counts as stopped below this speed (m/s)
STOPPED_SPEED = 0.1
#: stopped time is clipped to this (s)
STOPPED_MAX = 10.0


@dataclass
class StopClock:
    """Time (s) since the ego stopped (speed below :data:`STOPPED_SPEED`), 0 while moving,
    clipped to :data:`STOPPED_MAX`: the learned agents' only memory (it tells a wait at a stop
    sign that is over from one that has just begun)."""

    since: float | None = None

    def update(self, t: float, speed: float) -> float:
        if speed >= STOPPED_SPEED:
            self.since = None
            return 0.0
        if self.since is None:
            self.since = t
        return float(min(t - self.since, STOPPED_MAX))
