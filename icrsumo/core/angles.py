"""Angles in radians: the one wrap every heading comparison uses."""

from __future__ import annotations

import math


def wrap_angle(a: float) -> float:
    """``a`` (rad) wrapped to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def angle_diff(a: float, b: float) -> float:
    """|a - b| wrapped to [0, pi] (rad)."""
    return abs(wrap_angle(a - b))
