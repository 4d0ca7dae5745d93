"""The built-in lateral / longitudinal controller: future waypoints in the ego frame -> controls.

Waypoints: (N, 2) array, metres, ego frame (x forward, y left), spaced ``WAYPOINT_DT`` seconds
apart along the intended trajectory (as LMDrive / TransFuser heads predict). The desired speed
is the waypoints' spacing over time; steering is pure pursuit on the waypoint polyline.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .dynamics import Control, VehicleParams

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


@dataclass
class WaypointController:
    """Pure pursuit + PI speed control. Keeps an integral term: one instance per episode."""

    params: VehicleParams = field(default_factory=VehicleParams)
    kp: float = 0.6
    ki: float = 0.1
    _integral: float = 0.0

    def reset(self) -> None:
        self._integral = 0.0

    def control(self, waypoints: np.ndarray, speed: float, dt: float,
                target_speed: float | None = None) -> Control:
        """Controls that track ``waypoints`` (ego frame, m) from the current ``speed`` (m/s);
        ``target_speed`` (m/s) overrides the speed implied by the waypoints."""
        v_des = desired_speed(waypoints) if target_speed is None else target_speed
        lookahead = float(np.clip(2.5 + 0.6 * speed, 3.0, 15.0))
        px, py = pursuit_point(waypoints, lookahead)
        ld2 = max(px * px + py * py, 1e-6)
        curvature = 2.0 * py / ld2
        steer_angle = math.atan(self.params.wheelbase * curvature)
        steer = float(np.clip(steer_angle / self.params.max_steer, -1.0, 1.0))
        if v_des < 0.3:
            self._integral = 0.0
            return Control(steer=steer, throttle=0.0, brake=1.0 if speed > 0.05 else 0.6)
        err = v_des - speed
        self._integral = float(np.clip(self._integral + err * dt, -5.0, 5.0))
        u = self.kp * err + self.ki * self._integral
        if u >= 0:
            return Control(steer=steer, throttle=float(min(u, 1.0)), brake=0.0)
        return Control(steer=steer, throttle=0.0, brake=float(min(-u * 0.5, 1.0)))
