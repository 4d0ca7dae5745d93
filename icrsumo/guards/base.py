"""The guard protocol and what a guard sees (pure data, no SUMO).

A guard is reset once per episode with a :class:`GuardInfo` (the episode's public facts and,
for guards that declare ``needs_plan = True``, its :class:`NavPlan`: the route's maneuvers as a
car's navigation system knows them, never the episode's future) and then asked
``check(text, context)`` for every new instruction; it answers a :class:`~icrsumo.core.vocab.Verdict`
or ``(Verdict, reason)``, or repairs the instruction with ``(Verdict.REPAIR, reason, text)``: the
agent is shown ``text`` instead, which must name the plan's maneuver for that stretch. Anything
else is a :class:`GuardError`: the episode is stored as crashed with that reason.

What a blocked instruction leaves the agent is the run's block policy (:data:`BLOCK_POLICIES`):
``keep`` (what it was shown before) or ``navigator`` (the navigation plan's own instruction for the
stretch, in the route's baseline words: :class:`BaselineWords`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from icrsumo.agents.base import AgentTimeout
from icrsumo.core.defaults import BLOCK_POLICIES
from icrsumo.core.errors import Field, InputError, short
from icrsumo.core.types import Instruction, Intent, Maneuver
from icrsumo.core.vocab import Verdict

#: what the agent is shown when the first instruction of an episode is blocked
FALLBACK_TEXT = "Follow the road."
#: a reason is cut to this many characters
MAX_REASON = 200


#: what joins an agent's name and its guard's in a guarded row's name (and fingerprint)
GUARD_SEP = "+guard:"
#: what joins a guard's name and a block policy other than ``keep`` in a row's name
POLICY_SEP = "+"


def guarded_name(agent: str, guard: str, on_block: str = "keep") -> str:
    """The row name of ``agent`` behind ``guard`` (``AGENT+guard:NAME``; with a block policy
    other than keep, ``AGENT+guard:NAME+POLICY``)."""
    return f"{agent}{GUARD_SEP}{guard}{policy_suffix(on_block)}"


def check_policy(on_block: object) -> str:
    """``on_block`` when it is a block policy (:data:`BLOCK_POLICIES`); an InputError otherwise."""
    if not isinstance(on_block, str) or on_block not in BLOCK_POLICIES:
        raise InputError(Field("on_block"), short(on_block), "unknown block policy",
                         f"use {' or '.join(BLOCK_POLICIES)}")
    return on_block


def policy_suffix(on_block: str) -> str:
    """What block policy ``on_block`` adds to a guard's name in its rows ("" for keep)."""
    return "" if on_block == BLOCK_POLICIES[0] else f"{POLICY_SEP}{on_block}"


def split_row(name: str) -> tuple[str, str] | None:
    """(agent, guard) of a guarded row name, None for an unguarded one (the guard with its block
    policy: :func:`split_policy`)."""
    agent, sep, guard = name.rpartition(GUARD_SEP)
    return (agent, guard) if sep and agent and guard else None


def split_policy(guard: str) -> tuple[str, str]:
    """(guard name, block policy) of a row's guard part (``plan+navigator`` -> ("plan",
    "navigator"); ``plan`` -> ("plan", "keep"))."""
    for policy in BLOCK_POLICIES[1:]:
        suffix = policy_suffix(policy)
        if guard.endswith(suffix) and len(guard) > len(suffix):
            return guard[:-len(suffix)], policy
    return guard, BLOCK_POLICIES[0]


def guarded_fingerprint(agent_fp: str, guard_fp: str, on_block: str = "keep") -> str:
    """The fingerprint of a guarded row: its agent's and its guard's together (and its block
    policy, other than keep)."""
    from icrsumo.agents.identity import of_text

    return of_text(f"{agent_fp}{GUARD_SEP}{guard_fp}{policy_suffix(on_block)}")


class GuardError(RuntimeError):
    """A guard answered something other than pass / block / repair, or a repair that cannot be
    placed on the plan (the episode crashes with it)."""


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


def maneuver_at(maneuvers: Sequence[Maneuver], pos: float | None) -> int | None:
    """The index of the maneuver of ``maneuvers`` at route position ``pos`` (m; an
    instruction's ``maneuver_pos``, to the centimetre), None for none."""
    if pos is None:
        return None
    return next((i for i, m in enumerate(maneuvers) if round(m.pos, 2) == round(pos, 2)), None)


def intent_fits(intent: Intent, planned: Intent) -> bool:
    """Whether an instruction's ``intent`` is what the plan does where it does ``planned``
    (straight on also fits a maneuver that keeps to the road, e.g. a highway entry)."""
    return intent == planned or (intent is Intent.STRAIGHT and planned is Intent.FOLLOW)


class BaselineWords:
    """The route's baseline instructions (``baseline``) as the words of its ``maneuvers`` (sorted
    by position): what the navigator of asking answers (:mod:`icrsumo.sim.asking`) and what the
    ``navigator`` block policy shows for a blocked instruction (:mod:`icrsumo.guards.stream`)."""

    def __init__(self, maneuvers: Sequence[Maneuver], baseline: Sequence[Instruction]) -> None:
        self.maneuvers = tuple(maneuvers)
        #: maneuver index -> the baseline instructions for it, by trigger
        self.words: dict[int, list[Instruction]] = {}
        for i, m in enumerate(self.maneuvers):
            pos = round(m.pos, 2)
            mine = [ins for ins in baseline
                    if ins.maneuver_pos is not None and round(ins.maneuver_pos, 2) == pos]
            if mine:
                self.words[i] = sorted(mine, key=lambda ins: ins.trigger)

    def at(self, pos: float | None) -> int | None:
        """The index of the maneuver at route position ``pos`` (:func:`maneuver_at`)."""
        return maneuver_at(self.maneuvers, pos)

    def ahead(self, progress: float) -> int:
        """The index of the maneuver ahead at route ``progress`` (m): the first lane change whose
        start is not behind, or junction maneuver whose junction the ego has not left;
        ``len(maneuvers)`` when none is left."""
        def ahead(m: Maneuver) -> bool:
            return m.pos >= progress if m.kind.startswith("lane_change") else maneuver_over(m) > progress

        return next((i for i, m in enumerate(self.maneuvers) if ahead(m)), len(self.maneuvers))

    def wording(self, j: int | None, progress: float) -> Instruction | None:
        """The baseline instruction that words maneuver ``j`` at route ``progress`` (m): the
        last of its instructions triggered there, else the first (None: none, or no maneuver)."""
        mine = self.words.get(j, []) if j is not None else []
        shown = [ins for ins in mine if ins.trigger <= progress + 1e-9]
        return shown[-1] if shown else (mine[0] if mine else None)


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
    instruction's ``instruction_id``, the ``previous`` text the agent was shown through the guard
    (the last instruction it passed, or a repair; "" when none), and the navigation ``plan``
    (None for guards without ``needs_plan``)."""

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

    def check(self, text: str, context: GuardContext) -> (Verdict | tuple[Verdict, str]
                                                          | tuple[Verdict, str, str]): ...


@dataclass(frozen=True)
class Ruling:
    """A guard's answer read: its ``verdict``, one-line ``reason`` and, for a repair, the
    repaired ``text`` the agent is shown instead ("" otherwise)."""

    verdict: Verdict
    reason: str = ""
    text: str = ""


def ruling_of(answer: object, guard: str) -> Ruling:
    """The :class:`Ruling` of a guard's answer: a Verdict (or "pass" / "block"), a (Verdict,
    reason text) pair or a (Verdict.REPAIR, reason text, repaired text) triple; a
    :class:`GuardError` naming the guard for anything else, a repair without a repaired text,
    or a repaired text with a pass or a block."""
    reason: object = ""
    text: object = ""
    if isinstance(answer, tuple) and len(answer) in (2, 3):
        answer, reason, text = (*answer, "")[:3]
    try:
        verdict = Verdict(answer) if isinstance(answer, str) else None
    except ValueError:
        verdict = None
    if verdict is None or not isinstance(reason, str) or not isinstance(text, str):
        shown = repr(answer if verdict is None else reason if not isinstance(reason, str) else text)
        raise GuardError(f"guard {guard} returned {shown[:80]}, not pass / block / repair (or (verdict, "
                         "reason text), or (repair, reason text, repaired text))")
    if verdict is Verdict.REPAIR and not text.strip():
        raise GuardError(f"guard {guard} returned a repair without the repaired text (return "
                         "(Verdict.REPAIR, reason, text): the agent is shown text instead)")
    if verdict is not Verdict.REPAIR and text:
        raise GuardError(f"guard {guard} returned a repaired text with {verdict} (a repaired text "
                         "comes with Verdict.REPAIR only)")
    return Ruling(verdict, " ".join(reason.split())[:MAX_REASON], text)


def verdict_of(answer: object, guard: str) -> tuple[Verdict, str]:
    """(verdict, reason) of a guard's answer (:func:`ruling_of`, whose errors it raises)."""
    ruling = ruling_of(answer, guard)
    return ruling.verdict, ruling.reason
