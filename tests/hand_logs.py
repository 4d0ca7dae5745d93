"""Hand-built episode logs for the scoring tests (tests/scoring/), no SUMO.

Every log is a straight or L-shaped route, 20 Hz steps (0.05 s) and an ego centre moving
0.5 m per step from x = 0.25, so step i is at x = 0.25 + 0.5 i and passes the dense route's
point k (at x = k, direction +x) on the first step with x > k.
"""

from __future__ import annotations

from dataclasses import replace

from icrsumo.core.types import EpisodeLog, Event
from icrsumo.scoring.route import DenseRoute

DT = 0.05
#: a straight 100 m route along +x
ROUTE = ((0.0, 0.0), (100.0, 0.0))


def make_log(xy: list[tuple[float, float]], route: tuple[tuple[float, float], ...], *,
             speed: list[float] | None = None, outside: list[int] | None = None,
             events: tuple[Event, ...] = (), termination: str = "route_timeout") -> EpisodeLog:
    n = len(xy)
    t = tuple(round(DT * i, 3) for i in range(n))
    return EpisodeLog(
        route_id="r", agent="a", family="baseline", k=0, seed=1, step_length=DT,
        route_length=DenseRoute.from_polyline(route).length, t=t,
        x=tuple(p[0] for p in xy), y=tuple(p[1] for p in xy), yaw=(0.0,) * n,
        speed=tuple(speed) if speed is not None else (10.0,) * n, progress=(0.0,) * n,
        instruction=(0,) * n, outside=tuple(outside) if outside is not None else (0,) * n,
        route_dist=(0.0,) * n, events=events, termination=termination, termination_t=t[-1] if n else 0.0,
        route=route,
    )


def straight(n: int, y: float = 0.0) -> list[tuple[float, float]]:
    return [(0.25 + 0.5 * i, y) for i in range(n)]


def contact(kind: str, i: int, other: str) -> Event:
    """A contact event at step ``i`` (time and ego position of that step)."""
    return Event(kind, round(0.05 * i, 3), 0.0, other, 0.25 + 0.5 * i, 0.0)


def lb2_log(xy, *, speed=None, traffic=10.0, limit=10.0, outside=None, events=(), termination="completed"):
    """A log on :data:`ROUTE` with 2.0's columns: the other vehicles' mean speed and the lane's
    speed limit (m/s)."""
    log = make_log(xy, ROUTE, speed=speed, outside=outside, events=events, termination=termination)
    return replace(log, traffic_speed=(traffic,) * len(xy), speed_limit=(limit,) * len(xy))
