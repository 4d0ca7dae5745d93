"""What the rule sets share to turn a replayed episode into scores: the IS factor of each
penalised event kind (the same in Leaderboard 1.0 and 2.0: ``statistics_manager.py``'s
``PENALTY_*``), the collision contacts their ``CollisionTest`` counters see, and the rounded
:class:`~icrsumo.core.types.EpisodeResult`. Pure: no SUMO.
"""

from __future__ import annotations

from collections.abc import Sequence

from icrsumo.core.types import TERMINATIONS, EpisodeLog, EpisodeResult, Event, Infraction
from icrsumo.core.vocab import EventKind, Termination

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

#: Every event kind an :class:`~icrsumo.core.types.EpisodeLog` may hold.
EVENT_KINDS: frozenset[EventKind] = frozenset(EventKind)

#: CollisionTest (1.0 and 2.0): the last counted actor is remembered this long (s); static
#: layout never is
MAX_ID_TIME = 5.0

COLLISIONS = (EventKind.COLLISION_VEHICLE, EventKind.COLLISION_PEDESTRIAN, EventKind.COLLISION_STATIC)

#: the penalised event kinds that are not collisions: every such event counts
RULE_EVENTS = (EventKind.RED_LIGHT, EventKind.STOP_SIGN)


def contacts(events: Sequence[Event], last_id: str | None) -> list[tuple[Event, str]]:
    """The collision events among ``events`` with their actor ("" for the static layout, which
    has no identity), less those with ``last_id``, the actor of the last counted collision."""
    out = []
    for e in events:
        if e.kind in COLLISIONS:
            actor = e.other if e.kind != EventKind.COLLISION_STATIC else ""
            if not (actor and actor == last_id):
                out.append((e, actor))
    return out


def check_event_kinds(log: EpisodeLog) -> None:
    """ValueError naming the first event of ``log`` whose kind is not an :class:`EventKind`."""
    for e in log.events:
        if e.kind not in EVENT_KINDS:
            raise ValueError(f"unknown event kind {e.kind!r} at t={e.t} (known: {sorted(EVENT_KINDS)})")


def episode_result(log: EpisodeLog, rc: float, pct: float, infractions: tuple[Infraction, ...],
                   outside_m: float = 0.0) -> EpisodeResult:
    """The :class:`EpisodeResult` of ``log`` with RC ``rc``, IS the product of the
    ``infractions``' factors and DS = RC x IS: RC and DS rounded to 4 decimals, IS to 6,
    outside_lanes_pct (``pct``) to 4, duration to 3 and ``outside_m`` to 3, so results are
    stable across platforms."""
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
