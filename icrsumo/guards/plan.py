"""The ``plan`` guard: checks an instruction's intent against the navigation plan.

It sees what a car's navigation system has, the route's maneuvers ahead and the branches of
their junctions (:class:`~icrsumo.guards.base.NavPlan`), never what the episode will bring. It
blocks an instruction whose intent (the rule-based classifier's) contradicts the plan there:

* a turn or straight-on that is not the next junction maneuver's (or, when the ego is within
  :data:`AT_JUNCTION_M` of that one, the maneuver after it: an instruction for the following
  junction may arrive while the ego is still in this one), or any turn when no junction
  maneuver is left;
* a lane change to the side opposite the next lane change the route needs, or, with none
  before the next junction, one toward the side the route does not turn to.

Follow, stop and unknown intents and empty texts pass: they ask for nothing the plan rules out.
"""

from __future__ import annotations

from icrsumo.core.types import Intent
from icrsumo.core.vocab import Verdict
from icrsumo.instructions.intent import classify_intent

from .base import GuardContext, GuardInfo, NavPlan, PlanStep, intent_fits

#: m from a junction maneuver within which an instruction may already concern the next one
AT_JUNCTION_M = 30.0
_TURNS = frozenset({Intent.LEFT, Intent.RIGHT, Intent.STRAIGHT})
_LANES = {Intent.LANE_LEFT: Intent.LEFT, Intent.LANE_RIGHT: Intent.RIGHT}
_OTHER_LANE = {Intent.LANE_LEFT: Intent.LANE_RIGHT, Intent.LANE_RIGHT: Intent.LANE_LEFT}


def _fits(intent: Intent, step: PlanStep) -> bool:
    """Whether a turn / straight intent is what the plan does at ``step`` (:func:`intent_fits`)."""
    return intent_fits(intent, step.intent)


class PlanGuard:
    """``plan``: blocks instructions whose intent contradicts the navigation plan (module doc)."""

    name = "plan"
    needs_plan = True

    def reset(self, info: GuardInfo) -> None:  # noqa: ARG002 - nothing per episode
        return None

    def check(self, text: str, context: GuardContext) -> tuple[Verdict, str]:
        if not text.strip() or context.plan is None:
            return Verdict.PASS, ""
        return intent_ruling(classify_intent(text), context.plan)


def intent_ruling(intent: Intent, plan: NavPlan) -> tuple[Verdict, str]:
    """(verdict, reason) of an instruction that asks for ``intent`` where the navigation plan is
    ``plan``: the ``plan`` guard's rule (module doc), whoever read the intent (the ``llm`` guard
    has a language model read it)."""
    junctions = [s for s in plan.steps if not s.kind.startswith("lane_change")]
    if intent in _TURNS:
        if not junctions:
            return Verdict.BLOCK, f"{intent}, but the route has no junction maneuver left"
        near = junctions[:2] if junctions[0].distance < AT_JUNCTION_M else junctions[:1]
        if any(_fits(intent, s) for s in near):
            return Verdict.PASS, ""
        s = junctions[0]
        return Verdict.BLOCK, f"{intent}, but the plan goes {s.intent} in {max(s.distance, 0):.0f} m"
    if intent in _LANES:
        change = plan.next_lane_change()
        if change is not None:
            if change.intent == _OTHER_LANE[intent]:
                return Verdict.BLOCK, f"{intent}, but the route needs {change.intent} in " \
                                      f"{max(change.distance, 0):.0f} m"
            return Verdict.PASS, ""
        turn = junctions[0].intent if junctions else Intent.FOLLOW
        if turn in _LANES.values() and turn != _LANES[intent]:
            return Verdict.BLOCK, f"{intent}, but the route turns {turn} next"
    return Verdict.PASS, ""
