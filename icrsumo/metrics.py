"""Leaderboard 1.0 scoring of one recorded episode: RC, IS, DS. Pure: no SUMO.

RC (0-100) is the furthest route progress as a percentage of the route length, 100 once the
route counts as complete (see :func:`icrsumo.termination.is_route_complete`). IS (0-1) is the
product of one factor per penalised infraction (:data:`PENALTIES`) times
``1 - outside_lanes_pct / 100``. DS = RC * IS.
"""

from __future__ import annotations

import math

from icrsumo.termination import EPS, is_route_complete
from icrsumo.types import TERMINATIONS, EpisodeLog, EpisodeResult, Event, Infraction
from icrsumo.vocab import EventKind, Termination

#: IS factor of each penalised event kind (Leaderboard 1.0)
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

#: Collision events of one kind less than this many seconds apart are one collision when the
#: actor is unknown (static layout, or a vehicle/pedestrian event without ``other``).
COLLISION_RUN_GAP_S = 5.0

_ACTOR_COLLISIONS = (EventKind.COLLISION_VEHICLE, EventKind.COLLISION_PEDESTRIAN)


def route_completion(log: EpisodeLog) -> float:
    """RC in [0, 100], unrounded: 0 without steps; 100 when the log says completed or the
    furthest progress is >= 99 % of the route or within 10 m of its end."""
    if not log.progress:
        return 0.0
    best = max(log.progress)
    if log.termination == Termination.COMPLETED or is_route_complete(best, log.route_length):
        return 100.0
    if log.route_length <= 0:  # unreachable: a route of length <= 10 m is always complete
        return 0.0
    return min(100.0, max(0.0, 100.0 * best / log.route_length))


def step_distances(log: EpisodeLog) -> list[float]:
    """Distance (m) driven on each step: from the previous step's position (0 for the first)."""
    d = [0.0] * len(log.x)
    for i in range(1, len(log.x)):
        d[i] = math.hypot(log.x[i] - log.x[i - 1], log.y[i] - log.y[i - 1])
    return d


def outside_lanes_pct(log: EpisodeLog) -> float:
    """Percentage (0-100, unrounded) of the distance driven on steps with ``outside == 1``;
    0 when the ego did not move. Sums are exact (math.fsum) so results do not depend on order."""
    d = step_distances(log)
    total = math.fsum(d)
    if total <= 0.0:
        return 0.0
    out = math.fsum(di for di, o in zip(d, log.outside) if o == 1)
    return min(100.0, max(0.0, 100.0 * out / total))


def penalised_infractions(events: tuple[Event, ...] | list[Event]) -> tuple[Infraction, ...]:
    """The penalised infractions among ``events``, in time order, after de-duplication.

    collision_vehicle / collision_pedestrian: once per ``other`` actor id per episode (SUMO
    repeats a contact on every step of overlap). collision_static, and actor collisions with
    an empty ``other``: once per run of events less than 5 s apart. red_light and stop_sign:
    every event (the sensors emit one per junction entry). Unknown kinds raise ValueError.
    """
    seen_actors: set[tuple[str, str]] = set()
    last_anon: dict[str, float] = {}
    out: list[Infraction] = []
    for e in sorted(events, key=lambda ev: ev.t):
        if e.kind not in EVENT_KINDS:
            raise ValueError(f"unknown event kind {e.kind!r} at t={e.t} (known: {sorted(EVENT_KINDS)})")
        if e.kind not in PENALTIES:
            continue
        if e.kind in _ACTOR_COLLISIONS and e.other:
            key = (e.kind, e.other)
            if key in seen_actors:
                continue
            seen_actors.add(key)
        elif e.kind in _ACTOR_COLLISIONS or e.kind == EventKind.COLLISION_STATIC:
            prev = last_anon.get(e.kind)
            last_anon[e.kind] = e.t
            if prev is not None and e.t - prev < COLLISION_RUN_GAP_S - EPS:
                continue
        out.append(Infraction(kind=EventKind(e.kind), factor=PENALTIES[e.kind], t=e.t, pos=e.pos,
                              other=e.other))
    return tuple(out)


def score_episode(log: EpisodeLog) -> EpisodeResult:
    """Leaderboard 1.0 scores of one episode. RC and DS are rounded to 4 decimals, IS to 6,
    outside_lanes_pct to 4 and duration to 3, so results are stable across platforms."""
    if log.termination not in TERMINATIONS:
        raise ValueError(f"unknown termination {log.termination!r} (known: {sorted(TERMINATIONS)})")
    rc = route_completion(log)
    infractions = penalised_infractions(log.events)
    pct = outside_lanes_pct(log)
    is_ = 1.0
    for inf in infractions:
        is_ *= inf.factor
    is_ *= 1.0 - pct / 100.0
    duration = log.t[-1] - log.t[0] if len(log.t) >= 2 else 0.0
    return EpisodeResult(
        route_id=log.route_id,
        agent=log.agent,
        family=log.family,
        k=log.k,
        rc=round(rc, 4) + 0.0,
        is_=round(is_, 6) + 0.0,
        ds=round(rc * is_, 4) + 0.0,
        termination=Termination(log.termination),
        termination_class=TERMINATIONS[log.termination],
        infractions=infractions,
        outside_lanes_pct=round(pct, 4) + 0.0,
        duration=round(duration, 3) + 0.0,
    )
