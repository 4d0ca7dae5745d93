"""Asking for clarification: the navigator that answers an agent's asks (``Action.ask``) in an
episode run with asking on (``RunOptions.asking``).

The rules:

* **the answer** is the route's next maneuver as the baseline instructions word it: the maneuver
  ahead of the ego when it asked (a lane change whose start the ego has not passed, or a
  junction maneuver whose junction it has not left: :func:`icrsumo.guards.base.maneuver_over`),
  in the words of the baseline instruction the baseline sequence shows for that maneuver at
  the ego's position (the last of its instructions for it already triggered there, else the
  first); with no maneuver left, "Follow the road.";
* **the delay**: the answer arrives :data:`ASK_DELAY` simulated seconds after the ask, and the
  agent keeps driving meanwhile, so asking costs route time;
* **what the agent reads**: the answer replaces the instruction from its arrival until the next
  instruction is triggered (the agent's observations say so: ``Observation.answer``);
* **at most once per maneuver**: an ask about a maneuver already answered (or whose answer is
  on its way) is counted but not answered, so an agent that asks at every step gets one answer
  per maneuver;
* **every ask is stored** in the episode log (:class:`icrsumo.core.types.Ask`: time, route
  position, answered or not, the baseline instruction it was answered with).
"""

from __future__ import annotations

from collections.abc import Sequence

from icrsumo.core.types import Ask, Instruction, Maneuver
from icrsumo.guards.base import FALLBACK_TEXT, BaselineWords

#: simulated seconds between an ask and its answer (the agent keeps driving meanwhile)
ASK_DELAY = 2.0


class Navigator(BaselineWords):
    """Answers asks about a route's ``maneuvers`` (sorted by position) with the ``baseline``
    instructions' words for them (:class:`~icrsumo.guards.base.BaselineWords`: the maneuver
    ahead, worded as the baseline shows it there), ``delay`` s after each ask (module docstring
    for the rules)."""

    def __init__(self, maneuvers: Sequence[Maneuver], baseline: Sequence[Instruction],
                 delay: float = ASK_DELAY) -> None:
        super().__init__(maneuvers, baseline)
        self.delay = float(delay)
        #: every ask so far
        self.asks: list[Ask] = []
        self._answered: set[int] = set()
        self._pending: list[tuple[float, str, int]] = []   # (due s, text, id), in arrival order
        self._shown: tuple[str, int, int] | None = None    # (text, id, triggered index at arrival)

    def ask(self, t: float, progress: float) -> Ask:
        """Count an ask at time ``t`` (s) and route ``progress`` (m); the answer, if the maneuver
        ahead has none yet, arrives ``delay`` s later."""
        j = self.ahead(progress)
        answered = j not in self._answered
        words = self.wording(j, progress) if answered else None
        iid = words.id if words is not None else -1
        ask = Ask(round(t, 3) + 0.0, round(progress, 2) + 0.0, answered, iid)
        self.asks.append(ask)
        if answered:
            self._answered.add(j)
            text = words.rendered() if words is not None else FALLBACK_TEXT
            self._pending.append((t + self.delay, text, ask.instruction_id))
        return ask

    def shown(self, t: float, triggered: int) -> tuple[str, int] | None:
        """(text, instruction id) of the answer the agent reads at time ``t`` (s) while
        instruction index ``triggered`` is the last triggered one; None when no answer is shown."""
        while self._pending and self._pending[0][0] <= t + 1e-9:
            _, text, iid = self._pending.pop(0)
            self._shown = (text, iid, triggered)
        if self._shown is not None and self._shown[2] != triggered:
            self._shown = None
        return None if self._shown is None else self._shown[:2]
