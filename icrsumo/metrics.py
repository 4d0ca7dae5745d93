"""Leaderboard scoring of one recorded episode: RC, IS, DS. Pure: no SUMO.

Leaderboard 1.0 (``lb1``, the default) reproduces ``leaderboard/utils/statistics_manager.py``
(``compute_route_statistics``, branch ``leaderboard-1.0``) over the criteria of scenario_runner's
``atomic_criteria.py`` (branch ``leaderboard-1.0``), replayed from the log
(:func:`icrsumo.termination.run_monitor`):

* RC (0-100): ``RouteCompletionTest``'s percentage, 100 when the route was completed;
* IS (0-1): the product of one factor per counted infraction (:data:`PENALTIES`: collision
  with a pedestrian 0.50, a vehicle 0.60, the static layout 0.65, red light 0.70, stop sign
  0.80), times ``1 - pct / 100`` for ``OutsideRouteLanesTest``'s percentage when the ego made
  route progress off the driving lanes or in a lane of the opposite direction;
* DS = RC x IS.

Collisions are counted as ``CollisionTest`` counts them (:func:`counted_collisions`).

Leaderboard 2.0 (``lb2``) reproduces the 2.0 branches of the same files where they apply to
icrsumo's routes: RC rounded to 2 decimals, OutsideRouteLanesTest with 2.0's lane rules, its
``CollisionTest`` (:class:`CollisionCounter2`: one remembered place within 5 m, none while the
ego is below 0.1 m/s), MinimumSpeedRouteTest's factor ``1 - 0.3 (1 - pct / 100)`` per
checkpoint below 100 % of the other vehicles' mean speed (4 checkpoints), and the route
timeout of RouteTimeoutBehavior (:mod:`icrsumo.termination`). Scenario-specific criteria
(yield to an emergency vehicle, scenario timeouts) have no counterpart here.

:data:`SCORINGS` is the registry of scoring rules (a name is registered once).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

from icrsumo.termination import EPS, LB1_RULES, LB2_RULES, RouteRules, events_by_step, run_monitor
from icrsumo.types import TERMINATIONS, EpisodeLog, EpisodeResult, Event, Infraction
from icrsumo.vocab import EventKind, Termination

#: IS factor of each penalised event kind (statistics_manager.py: PENALTY_*)
PENALTIES: dict[EventKind, float] = {
    EventKind.COLLISION_PEDESTRIAN: 0.50,
    EventKind.COLLISION_VEHICLE: 0.60,
    EventKind.COLLISION_STATIC: 0.65,
    EventKind.RED_LIGHT: 0.70,
    EventKind.STOP_SIGN: 0.80,
}

#: Event kinds that are recorded but never penalised.
NON_PENALISED: tuple[EventKind, ...] = tuple(k for k in EventKind if k not in PENALTIES)

#: Every event kind an :class:`~icrsumo.types.EpisodeLog` may hold.
EVENT_KINDS: frozenset[EventKind] = frozenset(EventKind)

#: CollisionTest: a contact within this distance (m) of a counted one's place is not counted ...
MIN_AREA_OF_COLLISION = 3.0
#: ... and places are forgotten once the ego is farther than this (m) from them
MAX_AREA_OF_COLLISION = 5.0
#: CollisionTest: the last counted actor is remembered this long (s); static layout never is
MAX_ID_TIME = 5.0

COLLISIONS = (EventKind.COLLISION_VEHICLE, EventKind.COLLISION_PEDESTRIAN, EventKind.COLLISION_STATIC)


def _contacts(events: Sequence[Event], last_id: str | None) -> list[tuple[Event, str]]:
    """The collision events among ``events`` with their actor ("" for the static layout, which
    has no identity), less those with ``last_id``, the actor of the last counted collision."""
    out = []
    for e in events:
        if e.kind in COLLISIONS:
            actor = e.other if e.kind != EventKind.COLLISION_STATIC else ""
            if not (actor and actor == last_id):
                out.append((e, actor))
    return out


class CollisionCounter:
    """Leaderboard 1.0's ``CollisionTest``, step by step: :meth:`step` takes one step's time (s),
    ego centre (m) and events, and returns the collisions counted there.

    The log holds one event per step of contact. Per step, in order: each contact is ignored
    when it is with the same actor as the last counted collision (vehicles and pedestrians,
    by ``other``; the static layout has no identity) or when the ego is within 3 m of a place
    where a collision was counted; otherwise it is counted there. Then places farther than
    5 m from the ego are forgotten, and the last actor once more than 5 s passed since the last
    counted collision."""

    def __init__(self) -> None:
        self.places: list[tuple[float, float]] = []
        self.last_id: str | None = None
        self.last_t = 0.0

    def step(self, t: float, x: float, y: float, events: Sequence[Event]) -> list[Event]:
        out: list[Event] = []
        for e, actor in _contacts(events, self.last_id):
            if any(math.sqrt((x - px) ** 2 + (y - py) ** 2) <= MIN_AREA_OF_COLLISION
                   for px, py in self.places):
                continue
            out.append(e)
            self.last_t = t
            self.places.append((x, y))
            if actor:
                self.last_id = actor
        self.places = [(px, py) for px, py in self.places
                       if math.sqrt((x - px) ** 2 + (y - py) ** 2) <= MAX_AREA_OF_COLLISION]
        if self.last_id is not None and t - self.last_t > MAX_ID_TIME + EPS:
            self.last_id = None
        return out


def counted_collisions(log: EpisodeLog) -> list[Event]:
    """The collision events of ``log`` that :class:`CollisionCounter` counts, step by step (the
    positions are the ego centre of each step)."""
    by_step, _ = events_by_step(log)
    counter = CollisionCounter()
    out: list[Event] = []
    for i, evs in enumerate(by_step):
        if evs:
            out += counter.step(log.t[i], log.x[i], log.y[i], evs)
        elif counter.places or counter.last_id is not None:
            counter.step(log.t[i], log.x[i], log.y[i], ())
    return out


class CollisionCounter2:
    """Leaderboard 2.0's ``CollisionTest``, step by step (see :class:`CollisionCounter`): a
    contact is ignored when it is with the remembered actor, within 5 m of the one remembered
    place, or while the ego is below 0.1 m/s; a counted one replaces the place and time (and
    the actor, unless it is the static layout). The place is forgotten once the ego is more
    than 5 m from it, the actor 5 s after the last counted collision."""

    RADIUS = 5.0
    MIN_SPEED = 0.1

    def __init__(self) -> None:
        self.place: tuple[float, float] | None = None
        self.last_id: str | None = None
        self.last_t = 0.0

    def _near(self, x: float, y: float) -> bool:
        """Whether the ego centre (m) is within 5 m of the remembered place."""
        p = self.place
        return p is not None and math.sqrt((x - p[0]) ** 2 + (y - p[1]) ** 2) <= self.RADIUS

    def step(self, t: float, x: float, y: float, speed: float, events: Sequence[Event]) -> list[Event]:
        out: list[Event] = []
        for e, actor in _contacts(events, self.last_id):
            if self._near(x, y):
                continue
            if speed < self.MIN_SPEED:
                continue
            out.append(e)
            self.last_t, self.place = t, (x, y)
            if actor:
                self.last_id = actor
        if self.place is not None and not self._near(x, y):
            self.place = None
        if self.last_id is not None and t - self.last_t > MAX_ID_TIME + EPS:
            self.last_id = None
        return out


def counted_collisions_lb2(log: EpisodeLog) -> list[Event]:
    """The collision events of ``log`` that Leaderboard 2.0's CollisionTest counts."""
    by_step, _ = events_by_step(log)
    counter = CollisionCounter2()
    out: list[Event] = []
    for i, evs in enumerate(by_step):
        out += counter.step(log.t[i], log.x[i], log.y[i], log.speed[i], evs)
    return out


def penalised_infractions(log: EpisodeLog) -> tuple[Infraction, ...]:
    """The penalised event infractions of ``log`` in time order: the collisions
    :func:`counted_collisions` counts, and every red-light and stop-sign event (the sensors
    emit one per junction entry). Unknown event kinds raise ValueError."""
    for e in log.events:
        if e.kind not in EVENT_KINDS:
            raise ValueError(f"unknown event kind {e.kind!r} at t={e.t} (known: {sorted(EVENT_KINDS)})")
    chosen = counted_collisions(log) + [e for e in log.events
                                        if e.kind in (EventKind.RED_LIGHT, EventKind.STOP_SIGN)]
    return tuple(Infraction(kind=EventKind(e.kind), factor=PENALTIES[e.kind], t=e.t, pos=e.pos, other=e.other)
                 for e in sorted(chosen, key=lambda ev: ev.t))


def ended_by(log: EpisodeLog, rules: RouteRules) -> tuple[EpisodeLog, bool]:
    """The log as a fresh run under ``rules`` would have recorded it, and whether that is
    exact. The simulation does not depend on the rules, so where they end the episode on one of
    the log's steps, the log cut there (with that termination) is exactly that run's; where no
    rule of theirs fired by the log's end (it was recorded under rules that end sooner), the
    log is returned as it is and not exact."""
    log, exact, _ = _ended(log, rules)
    return log, exact


def _ended(log: EpisodeLog, rules: RouteRules):
    """:func:`ended_by` and the finished monitor of the returned log (one replay where the
    rules end the episode where it was recorded, the usual case)."""
    mon, end = run_monitor(log, rules)
    if end is None:
        return log, log.termination in (Termination.SIM_ERROR, Termination.STUCK), mon
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


def _score_lb1(log: EpisodeLog) -> EpisodeResult:
    log, _, mon = _ended(log, LB1_RULES)
    return _scored(log, mon, list(penalised_infractions(log)))


def _scored(log: EpisodeLog, mon, infractions: list[Infraction]) -> EpisodeResult:
    """RC, the outside-lanes infraction (only when route advance was made off the lanes) and
    2.0's minimum-speed infractions of a finished monitor, with ``infractions``."""
    rc = mon.completion_pct if mon is not None else 0.0
    pct = mon.outside_pct if mon is not None else 0.0
    if mon is not None and mon.outside_m > 0:
        infractions.append(Infraction(EventKind.OUTSIDE_ROUTE_LANES, 1.0 - pct / 100.0, log.t[-1],
                                      mon.progress, f"{mon.outside_m:.3f} m"))
    for i, value in enumerate(mon.min_speed if mon is not None else ()):
        if value < 100.0:
            factor = 1.0 - (1.0 - MIN_SPEED_FACTOR) * (1.0 - value / 100.0)
            infractions.append(Infraction(EventKind.MIN_SPEED, factor, log.t[-1], mon.progress,
                                          f"checkpoint {i + 1}: {value:.2f}%"))
    return _result(log, rc, pct, tuple(infractions), mon.outside_m if mon is not None else 0.0)


#: MinimumSpeedRouteTest's penalty value (2.0: PENALTY_PERC_DICT[MIN_SPEED_INFRACTION] = [0.7, 'decreases'])
MIN_SPEED_FACTOR = 0.7


def _score_lb2(log: EpisodeLog) -> EpisodeResult:
    log, _, mon = _ended(log, LB2_RULES)
    for e in log.events:
        if e.kind not in EVENT_KINDS:
            raise ValueError(f"unknown event kind {e.kind!r} at t={e.t} (known: {sorted(EVENT_KINDS)})")
    chosen = counted_collisions_lb2(log) + [e for e in log.events
                                            if e.kind in (EventKind.RED_LIGHT, EventKind.STOP_SIGN)]
    events = [Infraction(kind=EventKind(e.kind), factor=PENALTIES[e.kind], t=e.t, pos=e.pos, other=e.other)
              for e in sorted(chosen, key=lambda ev: ev.t)]
    return _scored(log, mon, events)


def _result(log: EpisodeLog, rc: float, pct: float, infractions: tuple[Infraction, ...],
            outside_m: float = 0.0) -> EpisodeResult:
    """RC and DS rounded to 4 decimals, IS to 6, outside_lanes_pct to 4 and duration to 3, so
    results are stable across platforms."""
    if log.termination not in TERMINATIONS:
        raise ValueError(f"unknown termination {log.termination!r} (known: {sorted(TERMINATIONS)})")
    is_ = 1.0
    for inf in infractions:
        is_ *= inf.factor
    duration = log.t[-1] - log.t[0] if len(log.t) >= 2 else 0.0
    return EpisodeResult(
        route_id=log.route_id, agent=log.agent, family=log.family, k=log.k,
        rc=round(rc, 4) + 0.0, is_=round(is_, 6) + 0.0, ds=round(rc * is_, 4) + 0.0,
        termination=Termination(log.termination), termination_class=TERMINATIONS[log.termination],
        infractions=infractions, outside_lanes_pct=round(pct, 4) + 0.0, duration=round(duration, 3) + 0.0,
        outside_m=round(outside_m, 3) + 0.0,
    )


@dataclass(frozen=True)
class Scoring:
    """One scoring rule set: ``name`` (``--scoring``), what it reproduces, and ``score``
    (an :class:`EpisodeLog` -> its :class:`EpisodeResult`)."""

    name: str
    title: str
    score: Callable[[EpisodeLog], EpisodeResult]


#: name -> scoring (:func:`register_scoring` refuses a name twice)
SCORINGS: dict[str, Scoring] = {}

#: the default scoring
DEFAULT_SCORING = "lb1"


def register_scoring(scoring: Scoring) -> Scoring:
    """Add ``scoring`` to :data:`SCORINGS`; ValueError when its name is taken."""
    if scoring.name in SCORINGS:
        raise ValueError(f"scoring {scoring.name!r} is registered already")
    SCORINGS[scoring.name] = scoring
    return scoring


register_scoring(Scoring("lb1", "CARLA Leaderboard 1.0 (branch leaderboard-1.0: statistics_manager.py, "
                                "atomic_criteria.py)", _score_lb1))
register_scoring(Scoring("lb2", "CARLA Leaderboard 2.0 (its statistics_manager.py, atomic_criteria.py, "
                                "RouteTimeoutBehavior), where it applies to icrsumo's routes", _score_lb2))


def scoring_names() -> Sequence[str]:
    """The registered scoring names, default first."""
    return [DEFAULT_SCORING] + sorted(n for n in SCORINGS if n != DEFAULT_SCORING)


def score_episode(log: EpisodeLog, scoring: str = DEFAULT_SCORING) -> EpisodeResult:
    """The scores of one episode under ``scoring`` (a name of :data:`SCORINGS`)."""
    try:
        rule = SCORINGS[scoring]
    except KeyError:
        raise ValueError(f"unknown scoring {scoring!r} (known: {', '.join(scoring_names())})") from None
    return rule.score(log)
