"""Decision-level attribution: what the ego did at each decision point of its route, as pure
functions over a recorded episode (no SUMO).

A *decision point* is a maneuver of the route other than following the road: a junction where
the route has a choice (turns, straight on, roundabouts, highway entries and exits) or a lane
change the route requires, at route position ``pos`` (m) and over by ``end`` (m; a lane
change's ``pos``). For each one of an episode:

- ``route_intent``: the branch the route takes (the maneuver's intent);
- ``text_intent``: the intent of the instruction active when the ego reached the decision (or
  when the episode ended, if it ended before), as the variant states it (its text classified,
  so a misleading "turn left" reads left, a blank text unknown);
- ``executed``: the branch the ego took: the route's when it passed the decision on the route;
  when it left the route there, the turn its heading made between the approach (:data:`APPROACH_M`
  before ``pos``) and the end of the episode (left / right over :data:`TURN_RAD`, else
  straight); None when it did not get there.

Outcome (:class:`~icrsumo.core.vocab.DecisionOutcome`): ``followed_route`` when the ego passed the
decision on the route; ``followed_text`` when it left the route there, the text disagreed with
the route and the ego took the text's branch; ``other`` when it left the route there otherwise;
``not_reached`` when the episode ended before (for any reason). A route deviation is charged to
the first decision not passed when the ego had come within :data:`APPROACH_M` of it, else to
none (it left the route between decisions).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from icrsumo.core.types import EpisodeLog, InstructionSet, Intent, Maneuver
from icrsumo.core.vocab import DecisionOutcome, Termination

#: m before a decision's position from which a route deviation is charged to it
APPROACH_M = 40.0
#: m beyond a decision's end after which the ego has passed it on the route
PASS_M = 10.0
#: rad of heading change above which a branch counts as a turn (45 degrees)
TURN_RAD = math.pi / 4
#: maneuver kinds that are no decision (following the road)
NOT_DECISIONS = frozenset({"follow"})


@dataclass(frozen=True)
class Decision:
    """One decision point of one episode. ``index``: its place among the route's decisions;
    ``kind``, ``pos`` (m), ``route_intent``: the maneuver; ``instruction_id`` (-1: none),
    ``text``, ``template`` (bank entry or noise operation id; the instruction type for the
    baseline) and ``text_intent``: the instruction active there; ``executed``: the branch the
    ego took (None: not reached); ``outcome``."""

    index: int
    kind: str
    pos: float
    route_intent: Intent
    instruction_id: int
    text: str
    template: str
    text_intent: Intent
    executed: Intent | None
    outcome: DecisionOutcome

    @property
    def contradicted(self) -> bool:
        """The text names another branch than the route's (an unknown or stop text names none)."""
        return contradicts(self.text_intent, self.route_intent)


def contradicts(text_intent: Intent, route_intent: Intent) -> bool:
    """Whether a text's intent names another branch than the route's."""
    return text_intent not in (route_intent, Intent.UNKNOWN, Intent.STOP)


def decision_points(maneuvers: Sequence[Maneuver]) -> tuple[Maneuver, ...]:
    """The route's decision points, in route order."""
    return tuple(sorted((m for m in maneuvers if m.kind not in NOT_DECISIONS), key=lambda m: m.pos))


def turn_of(yaw_in: float, yaw_out: float) -> Intent:
    """The branch a heading change (rad, counter-clockwise positive) makes: left, right or
    straight."""
    d = (yaw_out - yaw_in + math.pi) % (2 * math.pi) - math.pi
    return Intent.LEFT if d > TURN_RAD else Intent.RIGHT if d < -TURN_RAD else Intent.STRAIGHT


def _step_at(progress: Sequence[float], pos: float) -> int:
    """Index of the first step whose progress (m) reaches ``pos``, else the last step."""
    for i, p in enumerate(progress):
        if p >= pos:
            return i
    return len(progress) - 1


def classify_decisions(maneuvers: Sequence[Maneuver], iset: InstructionSet,
                       log: EpisodeLog) -> tuple[Decision, ...]:
    """The decisions of one episode (``log``) driven with the sequence ``iset``, on the route
    whose maneuvers are ``maneuvers`` (see the module docstring)."""
    from icrsumo.instructions.intent import classify_intent

    points = decision_points(maneuvers)
    by_id = {ins.id: ins for ins in iset.instructions}
    n = len(log.t)
    reached = log.progress[-1] if n else 0.0
    completed = log.termination == Termination.COMPLETED
    deviated = log.termination == Termination.ROUTE_DEVIATION
    charged = None  # the decision a route deviation is charged to
    if deviated:
        nxt = next((i for i, m in enumerate(points) if reached < max(m.end, m.pos) + PASS_M), None)
        if nxt is not None and reached >= points[nxt].pos - APPROACH_M:
            charged = nxt
    out = []
    for i, m in enumerate(points):
        step = _step_at(log.progress, m.pos) if n else -1
        iid = log.instruction[step] if n else -1
        ins = by_id.get(iid)
        text = ins.rendered() if ins is not None else ""
        text_intent = classify_intent(text) if ins is not None else Intent.UNKNOWN
        template = (ins.template or ins.type) if ins is not None else ""
        if completed or reached >= max(m.end, m.pos) + PASS_M:
            executed, outcome = m.intent, DecisionOutcome.FOLLOWED_ROUTE
        elif i == charged:
            before = _step_at(log.progress, m.pos - APPROACH_M / 4)
            executed = turn_of(log.yaw[before], log.yaw[-1])
            obeyed = contradicts(text_intent, m.intent) and _same_branch(executed, text_intent)
            outcome = DecisionOutcome.FOLLOWED_TEXT if obeyed else DecisionOutcome.OTHER
        else:
            executed, outcome = None, DecisionOutcome.NOT_REACHED
        out.append(Decision(i, m.kind, m.pos, m.intent, iid, text, template, text_intent, executed, outcome))
    return tuple(out)


def _same_branch(executed: Intent, text_intent: Intent) -> bool:
    """Whether the branch taken is the one the text names (following the road is going
    straight on; a lane change to one side shows as a turn to that side once off the route)."""
    return {Intent.FOLLOW: Intent.STRAIGHT, Intent.LANE_LEFT: Intent.LEFT,
            Intent.LANE_RIGHT: Intent.RIGHT}.get(text_intent, text_intent) == executed


def divergence(decisions: Sequence[Decision]) -> Decision | None:
    """The decision at which an episode that failed left its route: the one charged with the
    route deviation, else (another failure) the first one not reached; None when every decision
    was passed or none applies."""
    left = next((d for d in decisions if d.outcome in (DecisionOutcome.FOLLOWED_TEXT, DecisionOutcome.OTHER)),
                None)
    if left is not None:
        return left
    return next((d for d in decisions if d.outcome == DecisionOutcome.NOT_REACHED), None)


def answer_pairs(iset: InstructionSet, log: EpisodeLog) -> tuple[tuple[Intent, Intent], ...]:
    """(instructed intent, answered maneuver) of every question a language-model agent asked
    when its instruction changed (``log.model_calls`` with ``at`` "instruction"); the
    instructed intent is the instruction's text classified, as for :class:`Decision`."""
    from icrsumo.instructions.intent import classify_intent

    by_id = {ins.id: ins for ins in iset.instructions}
    out = []
    for c in log.model_calls:
        ins = by_id.get(c.instruction_id)
        if c.at == "instruction" and ins is not None:
            out.append((classify_intent(ins.rendered()), c.maneuver))
    return tuple(out)

