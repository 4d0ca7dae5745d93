"""The route criteria of the CARLA leaderboards as a pure, incremental monitor, shared by the
rule sets: each one (:mod:`icrsumo.scoring.lb1`, :mod:`icrsumo.scoring.lb2`) parametrises it with
its :class:`RouteRules`. No SUMO here.

Reproduces, rule by rule, scenario_runner's ``srunner/scenariomanager/scenarioatomics/
atomic_criteria.py`` as the leaderboard's ``leaderboard/scenarios/route_scenario.py`` builds
them for a route (the numbers below are branch ``leaderboard-1.0``'s; :class:`RouteRules`
says where 2.0 differs):

* ``RouteCompletionTest``: the percentage of the dense route
  (:class:`~icrsumo.scoring.route.DenseRoute`) passed (a point is passed when the ego is ahead
  of it along the route's direction there; 3 points are tried per tick), complete once that
  percentage is above 99 *and* the ego is less than 10 m (straight line) from the last route
  point; the test then reports success on the *next* tick (its ``update`` sets the status and
  returns RUNNING; the following one returns SUCCESS), so the route ends one step after the
  completing one, every criterion counting in that step (the others may still end it on the
  completing step itself);
* ``InRouteTest``: route deviation when the nearest of the next 6 dense points is 30 m or more
  away, or when the route advanced while the ego was 15 m or more from it exceeds 30 % of the
  route;
* ``OutsideRouteLanesTest``'s bookkeeping (the next 3 points are tried per tick, each one
  passed adding its straight-line distance from the last): the route advance made on ticks where the ego was
  off every driving lane or in a lane of the opposite direction, over all route advance (the
  lane facts themselves come from the sensors, :mod:`icrsumo.sim.lanes`, as the per-step
  ``outside`` flags of the log);
* ``ActorSpeedAboveThresholdTest`` (agent blocked): more than 180 s since the last tick at or
  above 0.1 m/s;
* the route timeout (``RouteScenario._estimate_route_timeout``): ``int(0.8 s/m x dense route
  length + 5 s)``, reached once more than that much simulated time has elapsed (``TimeOut``).

The closed loop (:mod:`icrsumo.sim.episode`) feeds :class:`TerminationMonitor` one step at a
time with the values the episode log stores (rounded as :mod:`icrsumo.results.logs` rounds them);
:func:`replay` runs the same monitor over a recorded :class:`~icrsumo.core.types.EpisodeLog`, so a
stored log is rescored to the same numbers and the same termination; :func:`ended_by` cuts a
log where other rules would have ended it.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

from icrsumo.core.types import EpisodeLog, Event
from icrsumo.core.vocab import EventKind, Termination

from .route import DenseRoute, dense_route

#: RouteCompletionTest.WINDOWS_SIZE: points tried per tick beyond the current one
COMPLETION_WINDOW = 2
#: RouteCompletionTest: complete above this percentage ...
COMPLETION_PCT = 99.0
#: ... and closer than this (m, straight line) to the last route point
COMPLETION_RADIUS_M = 10.0
#: InRouteTest.WINDOWS_SIZE, offroad_max (m), offroad_min (m) and MAX_ROUTE_PERCENTAGE (%)
IN_ROUTE_WINDOW = 5
DEVIATION_M = 30.0
SAFE_M = 15.0
MAX_OUT_ROUTE_PCT = 30.0
#: OutsideRouteLanesTest.WINDOWS_SIZE
LANES_WINDOW = 3
#: ActorSpeedAboveThresholdTest as the route scenario builds it: 0.1 m/s, 180 s
BLOCKED_SPEED = 0.1
BLOCKED_S = 180.0
#: route_scenario.py: SECONDS_GIVEN_PER_METERS, INITIAL_SECONDS_DELAY
SECONDS_PER_M = 0.8
INITIAL_DELAY_S = 5.0

#: bits of the per-step ``outside`` flag (OutsideRouteLanesTest): off every driving lane by more
#: than lane width / 2 + 1.3 m ...
OFF_LANES = 1
#: ... or in a lane of the opposite direction (outside junctions)
WRONG_LANE = 2
#: the same by Leaderboard 2.0's rules: off the lanes by more than width / 2 + 0.5 m ...
OFF_LANES_LB2 = 4
#: ... or in a lane of the opposite direction (2.0's wrong-lane rule)
WRONG_LANE_LB2 = 8

#: Tolerance (s) of the time comparisons: logged times are rounded to 1e-3 s, so this only
#: absorbs float noise such as 0.05 * 3600 != 180.0.
EPS = 1e-6

#: events that end a run by themselves -> termination kind (checked in this order)
ENDING_EVENTS: dict[EventKind, Termination] = {EventKind.SIM_ERROR: Termination.SIM_ERROR,
                                               EventKind.EGO_TELEPORT: Termination.STUCK}


def route_timeout(route_length: float) -> float:
    """Time budget (s) of a route of ``route_length`` m (the dense route's):
    ``int(0.8 * length + 5)``, truncated to whole seconds as the leaderboard does."""
    return float(int(SECONDS_PER_M * route_length + INITIAL_DELAY_S))


@dataclass(frozen=True)
class RouteRules:
    """The route criteria of one leaderboard version. ``outside_bits``: the per-step
    ``outside`` bits its OutsideRouteLanesTest reads; ``completion_decimals``: RC rounded to
    this many decimals before the > 99 % test (None: unrounded); ``timeout``: ``"route"``
    (1.0: int(0.8 s/m x length + 5 s)) or ``"progress"`` (2.0's RouteTimeoutBehavior: 300 s,
    plus the time to drive each metre of route advance at 10 % of the lane's speed limit);
    ``min_speed_checkpoints``: MinimumSpeedRouteTest's checkpoints (0: no such test)."""

    name: str
    outside_bits: int
    completion_decimals: int | None
    timeout: str
    min_speed_checkpoints: int


#: RouteTimeoutBehavior (2.0): MIN_TIMEOUT (s), TIMEOUT_ROUTE_PERC (%), window
MIN_TIMEOUT_LB2 = 300.0
TIMEOUT_ROUTE_PERC = 10.0
TIMEOUT_WINDOW = 3


class TerminationMonitor:
    """Decides, step by step, whether and why an episode ends, and keeps the leaderboard's route
    bookkeeping (RC, route advance off the lanes, 2.0's minimum-speed checkpoints).

    Per step, :meth:`locate` (the ego centre, m) then :meth:`update` (time s, speed m/s, the
    ``outside`` bits, the step's events, and for 2.0's rules the other vehicles' mean speed and
    the lane's speed limit, m/s). ``start_t`` is the simulation time from which the route
    timeout runs (the first logged step's: :func:`replay` uses ``log.t[0]``). Once a kind has
    been returned the monitor is finished and every later :meth:`update` returns the same kind;
    :meth:`finish` closes the bookkeeping at the end of the route.
    """

    def __init__(self, route: DenseRoute, start_t: float, rules: RouteRules) -> None:
        if not math.isfinite(start_t):
            raise ValueError(f"start_t must be finite, got {start_t!r}")
        self.route = route
        self.rules = rules
        self.start_t = float(start_t)
        self.timeout = route_timeout(route.length) if rules.timeout == "route" else MIN_TIMEOUT_LB2
        self._timeout_index = 0
        # MinimumSpeedRouteTest
        checkpoints = rules.min_speed_checkpoints
        self._checkpoint_m = route.length / checkpoints if checkpoints else 0.0
        self._checkpoint_at = 0.0
        self._speed_sums = [0.0, 0.0, 0]  # ego, traffic, points
        #: MinimumSpeedRouteTest's percentages (ego mean speed over the traffic's, %), per checkpoint
        self.min_speed: list[float] = []
        self._finished = False
        self.result: tuple[Termination, float] | None = None
        self._last_t: float | None = None
        self._last_valid: float | None = None  # ActorSpeedAboveThresholdTest._time_last_valid_state
        self.completion_index = 0                # RouteCompletionTest._current_index
        self.completed = False
        self._completion_reported = False        # the completing tick was seen: success on the next
        self._x = self._y = math.nan
        # InRouteTest
        self.in_route_index = 0
        self.route_dist = 0.0
        self._in_safe = True
        self._out_route_m = 0.0
        self._deviated = False
        # OutsideRouteLanesTest
        self.lanes_index = 0
        self.driven_m = 0.0
        self.outside_m = 0.0

    # ------------------------------------------------------------------ readings
    @property
    def progress(self) -> float:
        """Route progress (m): ``accum`` of the last dense point passed (monotone)."""
        return self.route.accum[self.completion_index]

    @property
    def completion_pct(self) -> float:
        """RouteCompletionTest's percentage (0-100, rounded as the rules round it); 100 once the
        route is complete."""
        if self.completed:
            return 100.0
        total = self.route.length
        pct = 100.0 * self.route.accum[self.completion_index] / total if total > 0 else 0.0
        dec = self.rules.completion_decimals
        return pct if dec is None else round(pct, dec)

    @property
    def outside_pct(self) -> float:
        """OutsideRouteLanesTest's percentage (0-100): route advance made off the lanes over all
        route advance made; 0 while none was made off the lanes."""
        return 100.0 * self.outside_m / self.driven_m if self.outside_m > 0 else 0.0

    def blocked_for(self, t: float) -> float:
        """Seconds since the last step at or above 0.1 m/s (0 before the first step)."""
        return 0.0 if self._last_valid is None else t - self._last_valid

    # ------------------------------------------------------------------ per step
    def locate(self, x: float, y: float) -> float:
        """Advance the route trackers to the ego centre (x, y) m; the route progress (m)."""
        if self.result is not None:
            return self.progress
        r, n = self.route, len(self.route.x)
        self._x, self._y = x, y
        # RouteCompletionTest: every point of the window the ego is ahead of moves the index
        cur = self.completion_index
        for i in range(cur, min(cur + COMPLETION_WINDOW + 1, n)):
            if r.passed(i, x, y):
                self.completion_index = i
        if not self.completed:
            self.completed = (self.completion_pct > COMPLETION_PCT if r.length > 0 else True) and \
                math.hypot(x - r.x[-1], y - r.y[-1]) < COMPLETION_RADIUS_M
        # InRouteTest: the nearest of the next points (the last of equals), its advance
        cur = self.in_route_index
        best, closest = math.inf, -1
        for i in range(cur, min(cur + IN_ROUTE_WINDOW + 1, n)):
            d = math.sqrt((x - r.x[i]) ** 2 + (y - r.y[i]) ** 2)
            if d <= best:
                closest, best = i, d
        self.route_dist = best
        off_route = True
        if best < DEVIATION_M:
            off_route = False
            self._in_safe = best < SAFE_M
        if closest != cur:
            if not self._in_safe:
                self._out_route_m += r.accum[closest] - r.accum[cur]
                if r.length > 0 and 100.0 * self._out_route_m / r.length > MAX_OUT_ROUTE_PCT:
                    off_route = True
            self.in_route_index = closest
        self._deviated = self._deviated or off_route
        return self.progress

    def update(self, t: float, speed: float, outside: int = 0, events: Sequence[Event] = (),
               traffic_speed: float = -1.0, speed_limit: float = 0.0) -> Termination | None:
        """Termination kind at this step (after :meth:`locate`) or None.

        Order of checks: a sim_error event, an ego_teleport event ('stuck'), completed,
        route_deviation, agent_blocked, route_timeout (elapsed > the budget)."""
        if self.result is not None:
            return self.result[0]
        if self._last_t is not None and t < self._last_t:
            raise ValueError(f"time went backwards: {t} after {self._last_t}")
        self._last_t = t
        blocked = False
        if speed < BLOCKED_SPEED and self._last_valid is not None:
            blocked = t - self._last_valid > BLOCKED_S + EPS
        else:
            self._last_valid = t
        # OutsideRouteLanesTest: each point of the window passed adds its advance from the last
        r, cur = self.route, self.lanes_index
        if not math.isnan(self._x):
            for i in range(cur + 1, min(cur + LANES_WINDOW + 1, len(r.x))):
                if r.passed(i, self._x, self._y):
                    j = self.lanes_index
                    gain = math.hypot(r.x[i] - r.x[j], r.y[i] - r.y[j])
                    self.lanes_index = i
                    self.driven_m += gain
                    if outside & self.rules.outside_bits:
                        self.outside_m += gain
        if self.rules.timeout == "progress" and not math.isnan(self._x):
            self._progress_timeout(speed_limit)
        if self.rules.min_speed_checkpoints and not math.isnan(self._x):
            if r.accum[self.completion_index] - self._checkpoint_at > self._checkpoint_m:
                self._close_checkpoint()
                self._checkpoint_at = r.accum[self.completion_index]
            if traffic_speed >= 0.0:
                self._speed_sums[0] += speed
                self._speed_sums[1] += traffic_speed
                self._speed_sums[2] += 1
        kind = self._check(t, events, blocked)
        if kind is not None:
            self.result = (kind, t)
        return kind

    def _progress_timeout(self, speed_limit: float) -> None:
        """RouteTimeoutBehavior (2.0): the last of the next points passed adds the time to drive
        its advance at 10 % of the speed limit (a limit of 0 adds nothing)."""
        r, cur = self.route, self._timeout_index
        new = cur
        for i in range(cur, min(cur + TIMEOUT_WINDOW + 1, len(r.x))):
            if r.passed(i, self._x, self._y):
                new = i
        if new > cur:
            if speed_limit > 0.0:
                self.timeout += (r.accum[new] - r.accum[cur]) / (speed_limit * TIMEOUT_ROUTE_PERC / 100.0)
            self._timeout_index = new

    def _close_checkpoint(self) -> None:
        """MinimumSpeedRouteTest: the ego's mean speed over the traffic's since the last
        checkpoint, in % rounded to 2 decimals (100 without samples or with standing traffic)."""
        ego, traffic, n = self._speed_sums
        self.min_speed.append(round(ego / n / (traffic / n) * 100.0, 2) if n and traffic != 0.0 else 100.0)
        self._speed_sums = [0.0, 0.0, 0]

    def finish(self) -> None:
        """The route ended: MinimumSpeedRouteTest closes a last checkpoint when more than 95 % of
        the route was driven (routes end near 99 %). Idempotent."""
        if self._finished:
            return
        self._finished = True
        r = self.route
        if self.rules.min_speed_checkpoints and r.length > 0 and \
                r.accum[self.completion_index] / r.length > 0.95:
            self._close_checkpoint()

    def _check(self, t: float, events: Sequence[Event], blocked: bool) -> Termination | None:
        if events:
            kinds = {e.kind for e in events}
            for event_kind, kind in ENDING_EVENTS.items():
                if event_kind in kinds:
                    return kind
        if self.completed:
            if self._completion_reported:
                return Termination.COMPLETED
            self._completion_reported = True  # RouteCompletionTest reports it on the next tick
        if self._deviated:
            return Termination.ROUTE_DEVIATION
        if blocked:
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


def run_monitor(log: EpisodeLog, rules: RouteRules
                ) -> tuple[TerminationMonitor | None, tuple[Termination, float] | None]:
    """The monitor (by ``rules``) run over the log's steps (None without steps), finished, and
    the first ``(kind, t)`` it decided, or, when no rule fired on the steps, the earliest
    sim_error / ego_teleport event after the last step (sim_error first on a tie), or None.
    2.0's rules need the log's ``traffic_speed`` and ``speed_limit`` columns (ValueError)."""
    by_step, trailing = events_by_step(log)
    mon = None
    if log.t:
        if rules.timeout == "progress" and not (log.traffic_speed and log.speed_limit):
            raise ValueError(f"{rules.name}'s rules need the traffic speed and speed limit of every step, "
                             "which this log does not record")
        mon = TerminationMonitor(dense_route(log), log.t[0], rules)
        two = rules.timeout == "progress"
        for i, evs in enumerate(by_step):
            mon.locate(log.x[i], log.y[i])
            kind = mon.update(log.t[i], log.speed[i], log.outside[i], evs,
                              log.traffic_speed[i] if two else -1.0, log.speed_limit[i] if two else 0.0)
            if kind is not None:
                mon.finish()
                return mon, (kind, log.t[i])
        mon.finish()
    ending = [e for e in trailing if e.kind in ENDING_EVENTS]
    if not ending:
        return mon, None
    t0 = ending[0].t
    kinds = {e.kind for e in ending if e.t <= t0 + EPS}
    return mon, (next(kind for ek, kind in ENDING_EVENTS.items() if ek in kinds), t0)


def replay(log: EpisodeLog, rules: RouteRules) -> tuple[Termination, float] | None:
    """The first ``(kind, t)`` the rules decide over the log (see :func:`run_monitor`)."""
    return run_monitor(log, rules)[1]


def ended_by(log: EpisodeLog, rules: RouteRules) -> tuple[EpisodeLog, bool]:
    """The log as a fresh run under ``rules`` would have recorded it, and whether that is
    exact. The simulation does not depend on the rules, so where they end the episode on one of
    the log's steps, the log cut there (with that termination) is exactly that run's; where no
    rule of theirs fired by the log's end (it was recorded under rules that end sooner), the
    log is returned as it is and not exact."""
    log, exact, _ = cut_at_end(log, rules)
    return log, exact


def cut_at_end(log: EpisodeLog, rules: RouteRules
               ) -> tuple[EpisodeLog, bool, TerminationMonitor | None]:
    """:func:`ended_by` and the finished monitor of the returned log (one replay where the
    rules end the episode where it was recorded, the usual case)."""
    mon, end = run_monitor(log, rules)
    if end is None:
        off_rules = (Termination.SIM_ERROR, Termination.STUCK, Termination.AGENT_ERROR)
        # a log of the loop's first rules ends on its completing step, one before the step on
        # which completion is reported: it is scored as completed, as it was recorded
        completed = log.termination == Termination.COMPLETED and mon is not None and mon.completed
        return log, log.termination in off_rules or completed, mon
    kind, t = end
    n = bisect.bisect_right(log.t, t + EPS)
    if n >= len(log.t) and kind == log.termination:
        return log, True, mon
    half = 0.5 * log.step_length + EPS
    cut = {f: getattr(log, f)[:n] for f in ("t", "x", "y", "yaw", "speed", "progress", "instruction",
                                               "outside", "route_dist", "traffic_speed", "speed_limit")}
    events = tuple(e for e in log.events if e.t <= t + half)
    log = replace(log, **cut, events=events, termination=kind, termination_t=t)
    return log, True, run_monitor(log, rules)[0]

