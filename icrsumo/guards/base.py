"""The guard protocol and what a guard sees (pure data, no SUMO).

A guard is reset once per episode with a :class:`GuardInfo` (the episode's public facts and,
for guards that declare ``needs_plan = True``, its :class:`NavPlan`: the route's maneuvers as a
car's navigation system knows them, never the episode's future) and then asked
``check(text, context)`` for every new instruction; it answers a :class:`~icrsumo.core.vocab.Verdict`
or ``(Verdict, reason)``. Anything else is a :class:`GuardError`: the episode is stored as
crashed with that reason.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from icrsumo.agents.base import AgentTimeout
from icrsumo.core.types import Intent, Maneuver
from icrsumo.core.vocab import Verdict

#: what the agent is shown when the first instruction of an episode is blocked
FALLBACK_TEXT = "Follow the road."
#: a reason is cut to this many characters
MAX_REASON = 200


#: what joins an agent's name and its guard's in a guarded row's name (and fingerprint)
GUARD_SEP = "+guard:"


def guarded_name(agent: str, guard: str) -> str:
    """The row name of ``agent`` behind ``guard``."""
    return f"{agent}{GUARD_SEP}{guard}"


def split_row(name: str) -> tuple[str, str] | None:
    """(agent, guard) of a guarded row name, None for an unguarded one."""
    agent, sep, guard = name.rpartition(GUARD_SEP)
    return (agent, guard) if sep and agent and guard else None


def guarded_fingerprint(agent_fp: str, guard_fp: str) -> str:
    """The fingerprint of a guarded row: its agent's and its guard's together."""
    from icrsumo.agents.identity import of_text

    return of_text(f"{agent_fp}{GUARD_SEP}{guard_fp}")


class GuardError(RuntimeError):
    """A guard answered something other than pass / block (the episode crashes with it)."""


class GuardTimeout(AgentTimeout):
    """A guard's ``reset`` or ``check`` did not answer within the agent calls' time limit
    (``agent_timeout``): the episode is stored as crashed with "guard NAME did not answer
    within N s", at once (as for a hung agent: no retry)."""


@dataclass(frozen=True)
class PlanStep:
    """One maneuver of the route ahead, as a navigation system announces it: ``kind``
    (turn_left, straight, roundabout, lane_change_left, ...), its ``intent``, ``distance`` (m
    from the ego's route position to where it starts; negative while the ego is in it),
    ``junction`` kind ("" for lane changes) and ``branches``: the intents the road offers there
    (left / straight / right ...; () for lane changes)."""

    kind: str
    intent: Intent
    distance: float
    junction: str = ""
    branches: tuple[Intent, ...] = ()


@dataclass(frozen=True)
class NavPlan:
    """The route's maneuvers not yet behind the ego (nearest first), at route ``progress`` (m)."""

    progress: float
    steps: tuple[PlanStep, ...]

    def next_junction(self) -> PlanStep | None:
        """The next maneuver at a junction (turns, straight on, roundabouts, highway ramps)."""
        return next((s for s in self.steps if not s.kind.startswith("lane_change")), None)

    def next_lane_change(self) -> PlanStep | None:
        """The next lane change the route needs, if it comes before the next junction maneuver."""
        first = self.steps[0] if self.steps else None
        return first if first is not None and first.kind.startswith("lane_change") else None

    def describe(self, n: int = 3) -> str:
        """One line for people and language models: the next ``n`` maneuvers."""
        if not self.steps:
            return "no maneuver left: follow the road to the destination"
        parts = []
        for s in self.steps[:n]:
            where = f"in {max(s.distance, 0.0):.0f} m"
            at = f" at the {s.junction.replace('_', ' ')}" if s.junction else ""
            offers = f" (branches: {', '.join(str(b) for b in s.branches)})" if s.branches else ""
            parts.append(f"{where}: {s.intent}{at}{offers}")
        return "; ".join(parts)


def maneuver_over(m: Maneuver) -> float:
    """The route position (m) from which maneuver ``m`` is behind the ego: a junction
    maneuver's ``end`` (the ego has left the junction), 30 m past a lane change."""
    return m.end if m.end > m.pos else m.pos + 30.0


def plan_at(maneuvers: tuple[Maneuver, ...], branches: dict[int, tuple[Intent, ...]],
            progress: float) -> NavPlan:
    """The :class:`NavPlan` at route ``progress`` (m) of a route's ``maneuvers`` (sorted by
    position; ``branches``: index -> the intents offered at that maneuver's junction). A
    maneuver stays in the plan until it is behind the ego (:func:`maneuver_over`)."""
    steps = []
    for i, m in enumerate(maneuvers):
        if maneuver_over(m) <= progress:
            continue
        steps.append(PlanStep(m.kind, m.intent, round(m.pos - progress, 2), m.junction, branches.get(i, ())))
    return NavPlan(round(progress, 2), tuple(steps))


@dataclass(frozen=True)
class GuardInfo:
    """What a guard learns at reset: the episode's route id and town (public facts; the
    navigation plan comes with each :class:`GuardContext`)."""

    route_id: str
    town: str


@dataclass(frozen=True)
class GuardContext:
    """What a guard sees with a new instruction: time ``t`` (s), route ``progress`` (m), the
    instruction's ``instruction_id``, the ``previous`` instruction text it passed ("" when none),
    and the navigation ``plan`` (None for guards without ``needs_plan``)."""

    t: float
    progress: float
    instruction_id: int
    previous: str
    plan: NavPlan | None = None


@runtime_checkable
class Guard(Protocol):
    """The guard protocol. ``name`` names the guarded rows (``AGENT+guard:NAME``);
    ``needs_plan``: whether ``check`` gets the navigation plan."""

    name: str
    needs_plan: bool

    def reset(self, info: GuardInfo) -> None: ...

    def check(self, text: str, context: GuardContext) -> Verdict | tuple[Verdict, str]: ...


def verdict_of(answer: object, guard: str) -> tuple[Verdict, str]:
    """(verdict, reason) of a guard's answer; a :class:`GuardError` naming the guard for
    anything but a Verdict (or "pass" / "block") or a (Verdict, reason text) pair."""
    reason: object = ""
    if isinstance(answer, tuple) and len(answer) == 2:
        answer, reason = answer
    try:
        verdict = Verdict(answer) if isinstance(answer, str) else None
    except ValueError:
        verdict = None
    if verdict is None or not isinstance(reason, str):
        shown = repr(answer if verdict is None else reason)
        raise GuardError(f"guard {guard} returned {shown[:80]}, not pass / block (or (verdict, reason text))")
    return verdict, " ".join(reason.split())[:MAX_REASON]
