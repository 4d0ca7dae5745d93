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
:data:`SCORINGS` is the registry of scoring rules (a name is registered once).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from icrsumo.termination import EPS, events_by_step, run_monitor
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
        for e in events:
            if e.kind not in COLLISIONS:
                continue
            actor = e.other if e.kind != EventKind.COLLISION_STATIC else ""
            if actor and actor == self.last_id:
                continue
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


def _score_lb1(log: EpisodeLog) -> EpisodeResult:
    mon, _ = run_monitor(log)
    rc = mon.completion_pct if mon is not None else 0.0
    pct = mon.outside_pct if mon is not None else 0.0
    infractions = list(penalised_infractions(log))
    if mon is not None and mon.outside_m > 0:
        end_t = log.t[-1]
        infractions.append(Infraction(EventKind.OUTSIDE_ROUTE_LANES, 1.0 - pct / 100.0, end_t, mon.progress,
                                      f"{mon.outside_m:.3f} m"))
    return _result(log, rc, pct, tuple(infractions))


def _result(log: EpisodeLog, rc: float, pct: float, infractions: tuple[Infraction, ...]) -> EpisodeResult:
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
