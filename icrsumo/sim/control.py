"""The built-in lateral / longitudinal controller: future waypoints in the ego frame -> controls.

Waypoints: (N, 2) array, metres, ego frame (x forward, y left), spaced ``WAYPOINT_DT`` seconds
apart along the intended trajectory (as LMDrive / TransFuser heads predict). The desired speed
is the waypoints' spacing over time; steering is pure pursuit on the waypoint polyline.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np

from icrsumo.world.dynamics import Control, VehicleParams

WAYPOINT_DT = 0.5  # s between consecutive waypoints


def desired_speed(waypoints: np.ndarray, dt: float = WAYPOINT_DT) -> float:
    """Speed (m/s) implied by the waypoint spacing: the first two segments, averaged."""
    pts = np.vstack([[0.0, 0.0], np.asarray(waypoints, dtype=float)[:2]])
    seg = np.hypot(*np.diff(pts, axis=0).T)
    return float(seg.mean() / dt) if len(seg) else 0.0


def pursuit_point(waypoints: np.ndarray, lookahead: float) -> np.ndarray:
    """The point at arc length ``lookahead`` (m) along the polyline origin -> waypoints."""
    pts = np.vstack([[0.0, 0.0], np.asarray(waypoints, dtype=float)])
    seg = np.hypot(*np.diff(pts, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    if cum[-1] < 1e-6:
        return np.array([lookahead, 0.0])
    if lookahead >= cum[-1]:
        d = pts[-1] - pts[-2] if seg[-1] > 1e-6 else np.array([1.0, 0.0])
        return pts[-1] + d / max(np.hypot(*d), 1e-6) * (lookahead - cum[-1])
    k = int(np.searchsorted(cum, lookahead, side="right") - 1)
    f = (lookahead - cum[k]) / max(seg[k], 1e-9)
    return pts[k] + f * (pts[k + 1] - pts[k])


class WaypointPath:
    """The polyline origin -> waypoints of one action, prepared once for :meth:`point`, which
    the controller calls every simulation step while the action is held (the agent acts every
    ``control_every`` steps). Same arithmetic as :func:`pursuit_point` and
    :func:`desired_speed`, so the results are identical, float for float."""

    __slots__ = ("xs", "ys", "seg", "cum", "total", "end", "speed")

    def __init__(self, waypoints: np.ndarray) -> None:
        wps = np.asarray(waypoints, dtype=float).reshape(-1, 2)
        xs, ys = [0.0, *wps[:, 0].tolist()], [0.0, *wps[:, 1].tolist()]
        dx = [xs[i + 1] - xs[i] for i in range(len(xs) - 1)]
        dy = [ys[i + 1] - ys[i] for i in range(len(ys) - 1)]
        seg = np.hypot(dx, dy).tolist() if dx else []
        cum, c = [0.0], 0.0
        for v in seg:  # np.cumsum's running sum
            c += v
            cum.append(c)
        self.xs, self.ys, self.seg, self.cum, self.total = xs, ys, seg, cum, cum[-1]
        #: unit direction beyond the last waypoint, as pursuit_point extrapolates
        e = (dx[-1], dy[-1]) if seg and seg[-1] > 1e-6 else (1.0, 0.0)
        n = max(float(np.hypot(e[0], e[1])), 1e-6)
        self.end = (e[0] / n, e[1] / n)
        #: desired_speed(waypoints): the mean of this polyline's first two segments over 0.5 s
        mean2 = (seg[0] + seg[1]) / 2 if len(seg) > 1 else seg[0] if seg else 0.0
        self.speed = mean2 / WAYPOINT_DT if seg else 0.0

    def point(self, lookahead: float) -> tuple[float, float]:
        """:func:`pursuit_point` of the waypoints (m, ego frame)."""
        total = self.total
        if total < 1e-6:
            return lookahead, 0.0
        if lookahead >= total:
            f = lookahead - total
            return self.xs[-1] + self.end[0] * f, self.ys[-1] + self.end[1] * f
        k = bisect.bisect_right(self.cum, lookahead) - 1
        f = (lookahead - self.cum[k]) / max(self.seg[k], 1e-9)
        xs, ys = self.xs, self.ys
        return xs[k] + f * (xs[k + 1] - xs[k]), ys[k] + f * (ys[k + 1] - ys[k])


@dataclass
class WaypointController:
    """Pure pursuit + PI speed control. Keeps an integral term: one instance per episode."""

    params: VehicleParams = field(default_factory=VehicleParams)
    kp: float = 0.6
    ki: float = 0.1
    _integral: float = 0.0

    def reset(self) -> None:
        self._integral = 0.0

    def control(self, waypoints: np.ndarray | WaypointPath, speed: float, dt: float,
                target_speed: float | None = None) -> Control:
        """Controls that track ``waypoints`` (ego frame, m; or a :class:`WaypointPath` of
        them) from the current ``speed`` (m/s); ``target_speed`` (m/s) overrides the speed
        implied by the waypoints."""
        path = waypoints if isinstance(waypoints, WaypointPath) else WaypointPath(waypoints)
        v_des = path.speed if target_speed is None else target_speed
        lookahead = float(min(max(2.5 + 0.6 * speed, 3.0), 15.0))
        px, py = path.point(lookahead)
        ld2 = max(px * px + py * py, 1e-6)
        curvature = 2.0 * py / ld2
        steer_angle = math.atan(self.params.wheelbase * curvature)
        steer = float(min(max(steer_angle / self.params.max_steer, -1.0), 1.0))
        if v_des < 0.3:
            self._integral = 0.0
            return Control(steer=steer, throttle=0.0, brake=1.0 if speed > 0.05 else 0.6)
        err = v_des - speed
        self._integral = float(min(max(self._integral + err * dt, -5.0), 5.0))
        u = self.kp * err + self.ki * self._integral
        if u >= 0:
            return Control(steer=steer, throttle=float(min(u, 1.0)), brake=0.0)
        return Control(steer=steer, throttle=0.0, brake=float(min(-u * 0.5, 1.0)))
