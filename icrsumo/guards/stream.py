"""A guard applied to an episode's instruction stream (what :class:`icrsumo.sim.episode.Episode`
uses when it runs with a guard): each new instruction is checked once, when it becomes active.
A passed one is shown; a repaired one (the guard's own repair) is replaced by the repaired text;
a blocked one leaves the agent what the block policy says (:data:`~icrsumo.guards.base.BLOCK_POLICIES`):
``keep``, what it was shown before ("Follow the road." before anything), or ``navigator``, the
navigation plan's own instruction for the stretch, in the route's baseline words (logged as a
repair)."""

from __future__ import annotations

import bisect
import time
from collections.abc import Callable, Sequence
from functools import cached_property

from icrsumo.core.errors import Field, InputError, short
from icrsumo.core.types import GuardDecision, Instruction, Intent, Maneuver
from icrsumo.core.vocab import Verdict
from icrsumo.instructions.intent import classify_intent
from icrsumo.instructions.maneuvers import extract_maneuvers
from icrsumo.world.networks import RoadNet
from icrsumo.world.scenario import Scenario

from .base import (
    FALLBACK_TEXT,
    BaselineWords,
    Guard,
    GuardContext,
    GuardError,
    GuardInfo,
    NavPlan,
    Ruling,
    check_policy,
    intent_fits,
    maneuver_at,
    plan_at,
    ruling_of,
)

_DIRECTION = {"s": Intent.STRAIGHT, "l": Intent.LEFT, "L": Intent.LEFT, "r": Intent.RIGHT, "R": Intent.RIGHT}
_ORDER = (Intent.LEFT, Intent.STRAIGHT, Intent.RIGHT)


def junction_branches(scenario: Scenario, net: RoadNet,
                      maneuvers: Sequence[Maneuver]) -> dict[int, tuple[Intent, ...]]:
    """Maneuver index -> the intents the road offers at its junction (from the edge the route
    enters it on: every connection's direction), for the junction maneuvers."""
    entries = {(j.junction, round(j.pos, 2)): j.from_edge for j in scenario.route.junctions}
    out = {}
    for i, m in enumerate(maneuvers):
        edge = entries.get((m.junction_id, round(float(m.pos), 2)))
        if not m.junction_id or edge is None:
            continue
        dirs = {_DIRECTION.get(c.direction) for to in net.successors.get(edge, ())
                for c in net.connections.get((edge, to), ())}
        out[i] = tuple(d for d in _ORDER if d in dirs)
    return out


class GuardedStream:
    """``guard`` between the instructions (``instructions``, their rendered ``texts``) and the
    agent, under block policy ``on_block`` (``navigator``: repairs are worded from ``baseline``,
    the route's baseline instructions). :meth:`shown` is called every step with the active
    index, :meth:`observed` says what the agent reads. The route's maneuvers are read when
    first needed: for the navigation plan of guards with ``needs_plan``, and for repairs."""

    def __init__(self, guard: Guard, scenario: Scenario, net: RoadNet, instructions: Sequence[Instruction],
                 texts: Sequence[str], on_block: str = "keep",
                 baseline: Sequence[Instruction] | None = None) -> None:
        self.guard, self.scenario, self.net = guard, scenario, net
        self.instr, self.texts = instructions, texts
        self.on_block = check_policy(on_block)
        if self.on_block == "navigator" and baseline is None:
            raise InputError(Field("baseline"), scenario.route_id,
                             "the navigator block policy needs the route's baseline instructions, whose "
                             "words replace blocked ones", "pass the baseline sequence of this route")
        self.baseline = tuple(baseline or ())
        self.name = str(getattr(guard, "name", type(guard).__name__))
        self.needs_plan = bool(getattr(guard, "needs_plan", False))
        self.decisions: list[GuardDecision] = []
        self.current = -1      # index of the instruction shown as written (-1: none)
        self.stand_in: tuple[str, int] | None = None  # (text, id) of a repair shown instead
        self.blocked = False   # a block came before anything was shown: the fallback text is shown
        self.previous = ""     # the last text shown through the guard (a passed one or a repair)
        self._checked = -1

    @cached_property
    def maneuvers(self) -> tuple[Maneuver, ...]:
        """The route's maneuvers (sorted by position)."""
        return tuple(extract_maneuvers(self.scenario, self.net))

    @cached_property
    def branches(self) -> dict[int, tuple[Intent, ...]]:
        """Maneuver index -> the intents its junction offers (:func:`junction_branches`)."""
        return junction_branches(self.scenario, self.net, self.maneuvers)

    @cached_property
    def words(self) -> BaselineWords:
        """The baseline instructions as the maneuvers' words (the navigator policy's repairs)."""
        return BaselineWords(self.maneuvers, self.baseline)

    def reset(self) -> None:
        self.guard.reset(GuardInfo(self.scenario.route_id, self.scenario.town))

    def plan(self, progress: float) -> NavPlan:
        return plan_at(self.maneuvers, self.branches, progress)

    def shown(self, k: int, t: float, progress: float) -> int:
        """The index of the instruction the agent is shown as written when ``k`` is active (-1:
        none, or a stand-in; the guard checks ``k`` the first time it is active)."""
        if k != self._checked and k >= 0:
            self._checked = k
            self._check(k, t, progress)
        return self.current

    def _check(self, k: int, t: float, progress: float) -> None:
        """Ask the guard about instruction ``k``, record its decision and what is shown now."""
        ins = self.instr[k]
        ctx = GuardContext(t=t, progress=progress, instruction_id=ins.id, previous=self.previous,
                           plan=self.plan(progress) if self.needs_plan else None)
        ruling, baseline_id = ruling_of(self.guard.check(self.texts[k], ctx), self.name), -1
        if ruling.verdict is Verdict.REPAIR:
            self._place(ins, ruling.text)
        elif ruling.verdict is Verdict.BLOCK and self.on_block == "navigator":
            words = self.words.wording(self.words.at(ins.maneuver_pos), progress)
            text = words.rendered() if words is not None else FALLBACK_TEXT
            ruling = Ruling(Verdict.REPAIR, ruling.reason, text)
            baseline_id = words.id if words is not None else -1
        self.decisions.append(GuardDecision(round(t, 3) + 0.0, round(progress, 2) + 0.0, ins.id,
                                            ruling.verdict, ruling.reason, ruling.text, baseline_id))
        if ruling.verdict is Verdict.PASS:
            self.current, self.stand_in, self.previous = k, None, self.texts[k]
        elif ruling.verdict is Verdict.REPAIR:
            self.current, self.previous = -1, ruling.text
            self.stand_in = (ruling.text, baseline_id if baseline_id >= 0 else ins.id)
        elif self.current < 0 and self.stand_in is None:
            self.blocked = True

    def _place(self, ins: Instruction, text: str) -> None:
        """A GuardError naming the guard unless its repaired ``text`` of instruction ``ins``
        reads (:func:`~icrsumo.instructions.intent.classify_intent`) as the plan's maneuver
        for that stretch: the maneuver the instruction stands for, or following the road."""
        j = maneuver_at(self.maneuvers, ins.maneuver_pos)
        planned = self.maneuvers[j].intent if j is not None else Intent.FOLLOW
        intent = classify_intent(text)
        if not intent_fits(intent, planned):
            raise GuardError(f"guard {self.name} repaired instruction {ins.id} as {short(text, 60)}, which "
                             f"reads as {intent}, not the plan's {planned} there (a repaired text must "
                             "name the plan's maneuver for that stretch)")

    def observed(self) -> tuple[str, int]:
        """(text, instruction id) the agent reads now: the instruction shown as written, a
        repair (its baseline instruction's id, else the repaired instruction's), "Follow the
        road." (-1) while a block came before anything was shown, else ("", -1)."""
        if self.stand_in is not None:
            return self.stand_in
        if self.current >= 0:
            return self.texts[self.current], self.instr[self.current].id
        return (FALLBACK_TEXT if self.blocked else ""), -1


def replay_checks(stream: GuardedStream,
                  clock: Callable[[], float] = time.perf_counter) -> tuple[list[GuardDecision], list[float]]:
    """The guard's decisions on ``stream``'s instructions as an episode that drives its whole
    route asks for them, without SUMO, and the wall time of each check (s, by ``clock``): the
    guard is reset, then each instruction that becomes active is checked once, in order, at its
    trigger (route progress, m; time 0 s). An episode checks it a step later, up to a metre or
    two further on, and stops checking where the episode ends. For measuring guards offline
    (``tools/benchmark.py --guards``); evaluations run :class:`GuardedStream` inside the episode."""
    stream.reset()
    triggers = [ins.trigger for ins in stream.instr]
    seconds = []
    for progress in sorted(set(triggers)):
        k = bisect.bisect_right(triggers, progress + 1e-9) - 1   # the episode's active instruction
        t0 = clock()
        stream.shown(k, 0.0, progress)
        seconds.append(clock() - t0)
    return list(stream.decisions), seconds
