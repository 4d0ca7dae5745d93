"""A guard applied to an episode's instruction stream (what :class:`icrsumo.sim.episode.Episode`
uses when it runs with a guard): each new instruction is checked once, when it becomes active;
the agent is shown the last one that passed."""

from __future__ import annotations

from collections.abc import Sequence

from icrsumo.core.types import GuardDecision, Instruction, Intent, Maneuver
from icrsumo.core.vocab import Verdict
from icrsumo.instructions.maneuvers import extract_maneuvers
from icrsumo.world.networks import RoadNet
from icrsumo.world.scenario import Scenario

from .base import FALLBACK_TEXT, Guard, GuardContext, GuardInfo, NavPlan, plan_at, verdict_of

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
    agent. :meth:`shown` is called every step with the active index; the navigation plan is
    built from the scenario's route maneuvers only for guards with ``needs_plan``."""

    def __init__(self, guard: Guard, scenario: Scenario, net: RoadNet, instructions: Sequence[Instruction],
                 texts: Sequence[str]) -> None:
        self.guard, self.scenario = guard, scenario
        self.instr, self.texts = instructions, texts
        self.name = str(getattr(guard, "name", type(guard).__name__))
        self.needs_plan = bool(getattr(guard, "needs_plan", False))
        self.maneuvers: tuple[Maneuver, ...] = ()
        self.branches: dict[int, tuple[Intent, ...]] = {}
        if self.needs_plan:
            self.maneuvers = tuple(extract_maneuvers(scenario, net))
            self.branches = junction_branches(scenario, net, self.maneuvers)
        self.decisions: list[GuardDecision] = []
        self.current = -1      # index of the instruction shown (-1: none)
        self.blocked = False   # a block came before any pass: the fallback text is shown
        self._checked = -1

    def reset(self) -> None:
        self.guard.reset(GuardInfo(self.scenario.route_id, self.scenario.town))

    def plan(self, progress: float) -> NavPlan:
        return plan_at(self.maneuvers, self.branches, progress)

    def shown(self, k: int, t: float, progress: float) -> int:
        """The index of the instruction the agent is shown when ``k`` is active (the guard
        checks ``k`` the first time it is active)."""
        if k != self._checked and k >= 0:
            self._checked = k
            ctx = GuardContext(t=t, progress=progress, instruction_id=self.instr[k].id,
                               previous=self.texts[self.current] if self.current >= 0 else "",
                               plan=self.plan(progress) if self.needs_plan else None)
            verdict, reason = verdict_of(self.guard.check(self.texts[k], ctx), self.name)
            self.decisions.append(GuardDecision(round(t, 3) + 0.0, round(progress, 2) + 0.0, self.instr[k].id,
                                                verdict, reason))
            if verdict is Verdict.PASS:
                self.current = k
            elif self.current < 0:
                self.blocked = True
        return self.current

    def text(self, shown: int) -> str:
        """What the agent reads when instruction ``shown`` is shown."""
        return self.texts[shown] if shown >= 0 else (FALLBACK_TEXT if self.blocked else "")
