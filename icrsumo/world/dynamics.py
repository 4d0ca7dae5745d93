"""Ego vehicle motion: a kinematic bicycle model with steering, acceleration and braking limits.

State at the vehicle's centre: x, y (m), yaw (rad, counter-clockwise from +x), speed (m/s),
steering angle (rad). Pure functions; SUMO only receives the resulting pose (moveToXY).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class VehicleParams:
    """Limits of the ego (a mid-size car). Lengths in m, angles in rad, rates per s."""

    length: float = 4.9
    width: float = 2.1
    wheelbase: float = 2.9
    max_steer: float = 0.6          # rad at the wheels
    max_steer_rate: float = 1.2     # rad/s
    max_accel: float = 3.0          # m/s^2 at full throttle
    max_brake: float = 8.0          # m/s^2 at full brake
    max_speed: float = 30.0         # m/s
    drag: float = 0.05              # m/s^2 per m/s of rolling / air resistance


@dataclass(frozen=True)
class EgoState:
    """Pose and motion of the ego's centre: x, y (m), yaw (rad), speed (m/s), steer (rad)."""

    x: float
    y: float
    yaw: float
    speed: float = 0.0
    steer: float = 0.0

    def front(self, length: float) -> tuple[float, float]:
        """Front-bumper centre (m): SUMO's vehicle position."""
        return (self.x + 0.5 * length * math.cos(self.yaw), self.y + 0.5 * length * math.sin(self.yaw))


@dataclass(frozen=True)
class Control:
    """Low-level controls: steer in [-1, 1] (positive = left), throttle and brake in [0, 1]."""

    steer: float = 0.0
    throttle: float = 0.0
    brake: float = 0.0


def _clip(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else hi if v > hi else v


def step(state: EgoState, control: Control, dt: float, p: VehicleParams = VehicleParams()) -> EgoState:
    """Advance the bicycle model by ``dt`` seconds (semi-implicit Euler)."""
    target = _clip(control.steer, -1.0, 1.0) * p.max_steer
    max_d = p.max_steer_rate * dt
    steer = state.steer + _clip(target - state.steer, -max_d, max_d)
    accel = _clip(control.throttle, 0.0, 1.0) * p.max_accel - _clip(control.brake, 0.0, 1.0) * p.max_brake
    accel -= p.drag * state.speed
    speed = _clip(state.speed + accel * dt, 0.0, p.max_speed)
    lr = 0.5 * p.wheelbase
    beta = math.atan(0.5 * math.tan(steer))
    v = 0.5 * (state.speed + speed)
    yaw = state.yaw + v / lr * math.sin(beta) * dt
    x = state.x + v * math.cos(state.yaw + beta) * dt
    y = state.y + v * math.sin(state.yaw + beta) * dt
    yaw = (yaw + math.pi) % (2 * math.pi) - math.pi
    return EgoState(x, y, yaw, speed, steer)
