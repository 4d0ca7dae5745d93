"""Run-ending rules of Leaderboard 1.0 as a pure, incremental monitor.

The closed loop (:mod:`icrsumo.sim.episode`) calls :meth:`TerminationMonitor.update` once per
simulation step; :func:`replay` runs the same monitor over a recorded
:class:`~icrsumo.types.EpisodeLog`, so a log can be checked against the rules that ended it.
No SUMO here.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence

from icrsumo.types import EpisodeLog, Event
from icrsumo.vocab import EventKind, Termination

DEVIATION_M = 30.0
BLOCKED_SPEED = 0.1
BLOCKED_S = 180.0
COMPLETION_FRACTION = 0.99
COMPLETION_RADIUS_M = 10.0

#: Tolerance of the comparisons below (s and m). Logged values are rounded to 1e-3 s and
#: 0.01 m, so this only absorbs float noise such as 0.1 * 1800 != 180.0.
EPS = 1e-6

#: events that end a run by themselves -> termination kind (checked in this order)
ENDING_EVENTS: dict[EventKind, Termination] = {EventKind.SIM_ERROR: Termination.SIM_ERROR,
                                               EventKind.EGO_TELEPORT: Termination.STUCK}


def route_timeout(route_length: float) -> float:
    """Time budget (s) of a route: 0.8 s per metre plus 5 s."""
    return 0.8 * route_length + 5.0


def is_route_complete(progress: float, route_length: float) -> bool:
    """True when ``progress`` (m) counts as having finished the route: at least 99 % of its
    length, or within 10 m of its end. Shared by the monitor and by RC scoring."""
    return (progress >= COMPLETION_FRACTION * route_length - EPS
            or route_length - progress <= COMPLETION_RADIUS_M + EPS)


class TerminationMonitor:
    """Decides, step by step, whether and why an episode ends.

    ``start_t`` is the simulation time from which the route timeout runs (the time of the
    first logged step: :func:`replay` uses ``log.t[0]``). Once a kind has been returned the
    monitor is finished and every later :meth:`update` returns the same kind.
    """

    def __init__(self, route_length: float, start_t: float) -> None:
        if not math.isfinite(route_length) or route_length < 0:
            raise ValueError(f"route_length must be finite and >= 0, got {route_length!r}")
        if not math.isfinite(start_t):
            raise ValueError(f"start_t must be finite, got {start_t!r}")
        self.route_length = float(route_length)
        self.start_t = float(start_t)
        self.timeout = route_timeout(self.route_length)
        self.slow_since: float | None = None
        self.result: tuple[Termination, float] | None = None
        self._last_t: float | None = None

    def blocked_for(self, t: float) -> float:
        """Seconds the ego has been continuously slow at time ``t`` (0 when it is moving)."""
        return 0.0 if self.slow_since is None else t - self.slow_since

    def update(self, t: float, progress: float, route_dist: float, speed: float,
               events: Sequence[Event] = ()) -> Termination | None:
        """Termination kind at this step or None.

        Order of checks: a sim_error event, an ego_teleport event ('stuck'), completed
        (progress >= 0.99 L or L - progress <= 10 m), route_deviation (route_dist > 30 m),
        agent_blocked (speed < 0.1 m/s continuously for >= 180 s of simulated time, measured
        from the first slow step), route_timeout (t - start_t > 0.8 L + 5 s).
        """
        if self.result is not None:
            return self.result[0]
        if self._last_t is not None and t < self._last_t:
            raise ValueError(f"time went backwards: {t} after {self._last_t}")
        self._last_t = t
        if speed < BLOCKED_SPEED:
            if self.slow_since is None:
                self.slow_since = t
        else:
            self.slow_since = None
        kind = self._check(t, progress, route_dist, events)
        if kind is not None:
            self.result = (kind, t)
        return kind

    def _check(self, t: float, progress: float, route_dist: float,
               events: Sequence[Event]) -> Termination | None:
        if events:
            kinds = {e.kind for e in events}
            for event_kind, kind in ENDING_EVENTS.items():
                if event_kind in kinds:
                    return kind
        if is_route_complete(progress, self.route_length):
            return Termination.COMPLETED
        if route_dist > DEVIATION_M + EPS:
            return Termination.ROUTE_DEVIATION
        if self.slow_since is not None and t - self.slow_since >= BLOCKED_S - EPS:
            return Termination.AGENT_BLOCKED
        if t - self.start_t > self.timeout + EPS:
            return Termination.ROUTE_TIMEOUT
        return None


def events_by_step(log: EpisodeLog) -> tuple[list[list[Event]], list[Event]]:
    """The log's events attached to its steps, and the events after the last step.

    Each event goes to the step whose ``t`` is nearest (the earlier one on a tie) when that is
    within half a step. Events more than half a step after the last step (the loop records
    ``ego_teleport`` / ``sim_error`` at a time for which it logged no step) are returned as the
    trailing list; events more than half a step before the first step are dropped.
    """
    n = len(log.t)
    out: list[list[Event]] = [[] for _ in range(n)]
    trailing: list[Event] = []
    half = 0.5 * log.step_length + EPS
    for e in sorted(log.events, key=lambda ev: ev.t):
        if n == 0 or e.t > log.t[-1] + half:
            trailing.append(e)
            continue
        i = bisect.bisect_left(log.t, e.t)
        cands = [j for j in (i - 1, i) if 0 <= j < n]
        j = min(cands, key=lambda c: (abs(log.t[c] - e.t), c))
        if abs(log.t[j] - e.t) <= half:
            out[j].append(e)
    return out, trailing


def replay(log: EpisodeLog) -> tuple[Termination, float] | None:
    """Run the monitor over the log's columns (events attached to the step with the same t,
    within half a step) and return the first ``(kind, t)``, or None if no rule fired.

    If no rule fired on the steps, the earliest sim_error / ego_teleport event after the last
    step ends the run at that event's time (sim_error first on a tie)."""
    by_step, trailing = events_by_step(log)
    if log.t:
        mon = TerminationMonitor(log.route_length, log.t[0])
        for i, evs in enumerate(by_step):
            kind = mon.update(log.t[i], log.progress[i], log.route_dist[i], log.speed[i], evs)
            if kind is not None:
                return kind, log.t[i]
    ending = [e for e in trailing if e.kind in ENDING_EVENTS]
    if not ending:
        return None
    t0 = ending[0].t
    kinds = {e.kind for e in ending if e.t <= t0 + EPS}
    return next(kind for ek, kind in ENDING_EVENTS.items() if ek in kinds), t0
