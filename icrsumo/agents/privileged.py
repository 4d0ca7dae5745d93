"""Privileged built-in agents: ``route-oracle`` and ``instruction-follower``.

Both drive the same way: plan a lane path ahead on the map (lanes, junction-internal lanes),
track it with waypoints, and set the speed from the speed limit, curvature, the gap to
vehicles and pedestrians on the path, traffic-light states and stop signs. They differ only in
how they choose the next edge at a junction:

- route-oracle follows the scenario's route and ignores the instruction (instruction-blind
  upper bound);
- instruction-follower does not know the route: it classifies the active instruction with the
  intent classifier and takes the branch it names at the next junction (left / right /
  straight; roundabout exit 1 = right, 2 = straight, 3 = left; highway exit = right), changes
  lane when told, and otherwise (follow, unclear) keeps the current road: straight where
  possible, else the only way on, else right. With asking on (``EpisodeInfo.asking``) it asks
  the navigator (``Action.ask``) when it cannot place the intent of a new instruction (unknown,
  or an empty text), unless the navigator's last answer is a junction maneuver it has not yet
  driven: that answer then stands for the unclear instruction.

:class:`~icrsumo.agents.driver.PathDriver` (the lane path) and
:class:`~icrsumo.agents.speed.SpeedPolicy` (the speed) are the driving they share; their names
(the constants, :func:`arrival_time`, :class:`PathDriver`) are re-exported here, deprecated:
import them from those modules.
"""

from __future__ import annotations

import re
from dataclasses import replace

from icrsumo.core.types import Intent
from icrsumo.instructions.intent import classify_intent

from .base import Action, EpisodeInfo, Observation, World
from .driver import (
    CHANGE_GAP_TIME,
    CHANGE_LOOK_BEHIND,
    HORIZON,
    LANE_CHANGE_M,
    WAIT_BEFORE_END,
    PathDriver,
    lane_edge,
)
from .speed import (
    COMFORT_DECEL,
    CONFLICT_CLEAR,
    CORRIDOR,
    CRUISE_FACTOR,
    FOE_ACCEL,
    FOE_TOP_SPEED,
    HARD_DECEL,
    LAT_ACCEL,
    LINE_HOLD,
    LINE_HOLD_SPEED,
    MERGE_MARGIN,
    MIN_GAP,
    MINOR_ENTRY_SPEED,
    MOVING,
    PED_MOVING,
    QUEUE_HEAD_M,
    STANDING_CLEAR,
    STANDING_WAIT,
    STOP_LAG,
    STOP_MARGIN,
    STOP_SIGN_WAIT,
    SWEPT_MARGIN,
    UNSEEN_SPEED,
    YIELD_APPROACH,
    YIELD_LOOKAHEAD,
    YIELD_MARGIN,
    YIELD_TIME,
    arrival_time,
)

#: the driving's names, re-exported (deprecated: import them from driver and speed)
__all__ = [
    "CHANGE_GAP_TIME", "CHANGE_LOOK_BEHIND", "COMFORT_DECEL", "CONFLICT_CLEAR", "CORRIDOR",
    "CRUISE_FACTOR", "FOE_ACCEL", "FOE_TOP_SPEED", "HARD_DECEL", "HORIZON", "LANE_CHANGE_M",
    "LAT_ACCEL", "LINE_HOLD", "LINE_HOLD_SPEED", "MERGE_MARGIN", "MINOR_ENTRY_SPEED", "MIN_GAP",
    "MOVING", "PED_MOVING", "QUEUE_HEAD_M", "STANDING_CLEAR", "STANDING_WAIT", "STOP_LAG",
    "STOP_MARGIN", "STOP_SIGN_WAIT", "SWEPT_MARGIN", "UNSEEN_SPEED", "WAIT_BEFORE_END",
    "YIELD_APPROACH", "YIELD_LOOKAHEAD", "YIELD_MARGIN", "YIELD_TIME", "InstructionFollower",
    "PathDriver", "RouteOracle", "arrival_time",
]


class RouteOracle(PathDriver):
    """Follows the scenario's route; ignores the instruction (an instruction-blind upper bound)."""

    name = "route-oracle"
    #: the only agent handed the route (World.route); every other one gets None
    needs_route = True

    def __init__(self) -> None:
        super().__init__()
        # index into the route's edges of the edge the ego was last found on: a route may drive
        # one road twice (around a block and back), and each visit leaves it its own way
        self._at = 0

    def reset(self, info: EpisodeInfo) -> None:
        super().reset(info)
        self._at = 0

    def entered(self, w: World, edge: str) -> None:
        i = self._occurrence(w, edge)
        if i is not None:
            self._at = i

    def _occurrence(self, w: World, edge: str) -> int | None:
        """Index of ``edge`` on the route: its first occurrence at or after the ego's (the
        first anywhere when the ego has left the route; None if the route never drives it)."""
        edges = w.route.edges if w.route is not None else ()
        for start in (self._at, 0):
            try:
                return edges.index(edge, start)
            except ValueError:
                pass
        return None

    def choose(self, w: World, edge: str, options: list[str], tentative: bool) -> str | None:
        i = self._occurrence(w, edge)
        edges = w.route.edges if w.route is not None else ()
        return edges[i + 1] if i is not None and i + 1 < len(edges) else None


#: words that name a roundabout in an instruction
_RING_WORDS = re.compile(r"roundabout|traffic circle|rotary|\bcircle\b", re.IGNORECASE)
#: the navigator's answers that are held until driven (junction maneuvers)
_HELD = (Intent.LEFT, Intent.RIGHT, Intent.STRAIGHT)


class InstructionFollower(PathDriver):
    """Knows the map, not the route: takes the branch the active instruction names."""

    name = "instruction-follower"

    def __init__(self) -> None:
        super().__init__()
        self.intent = Intent.FOLLOW
        # the instruction read last: (id, whether it was the navigator's answer)
        self._instr_id: tuple[int, bool] = (-1, False)
        # asking: whether the navigator answers asks; ask with this step's action; the
        # navigator's last junction answer not yet driven
        self.asking = False
        self._ask_now = False
        self._held: Intent | None = None
        self._lane_done: set[tuple[int, bool]] = set()
        # the lane (edge, index) the active lane-change instruction asks for, and the one an
        # earlier unfinished lane-change instruction asked for (consecutive instructions add up)
        self._lane_goal: tuple[str, int] | None = None
        self._lane_carry: tuple[str, int] | None = None
        # the active instruction names a roundabout: at its entry the ring is taken, not a bypass
        self._ring_named = False
        self._ring_exits = 0
        # the edge at whose end the active instruction's maneuver was committed to: an
        # instruction names one junction, so the junctions after it are driven by the road
        self._spent: str | None = None

    def reset(self, info: EpisodeInfo) -> None:
        super().reset(info)
        self.intent = Intent.FOLLOW
        self._instr_id = (-1, False)
        self.asking = bool(getattr(info, "asking", False))
        self._ask_now = False
        self._held = None
        self._lane_done = set()
        self._lane_goal = self._lane_carry = None
        self._ring_named = False
        self._ring_exits = 0
        self._spent = None

    def act(self, obs: Observation) -> Action:
        self._ask_now = False
        action = super().act(obs)
        return replace(action, ask=True) if self._ask_now else action

    def observe(self, obs: Observation) -> None:
        if (obs.instruction_id, obs.answer) != self._instr_id:
            unfinished = self._lane_goal is not None and self._instr_id not in self._lane_done
            self._lane_carry = self._lane_goal if unfinished else None
            self._lane_goal = None
            self._instr_id = (obs.instruction_id, obs.answer)
            self.intent = self.placed(self.interpret(obs), obs)
            self._ring_named = bool(_RING_WORDS.search(obs.instruction or ""))
            self._spent = None
            # a new instruction before a junction is entered may name another branch there:
            # the branch is chosen again (a route that starts a few metres before a junction
            # meets its turn instruction after the choice was made; inside a long junction the
            # ego has already chosen at the short edge beyond it)
            lane = obs.world.lane if obs.world is not None else ""
            if lane.startswith(":"):
                self._decided.pop(self.net.via_edges.get(lane, ("", ""))[1], None)
            elif lane:
                self._decided.pop(lane_edge(lane), None)

    def placed(self, intent: Intent, obs: Observation) -> Intent:
        """The intent to drive by when ``obs``'s instruction reads as ``intent``: itself, unless
        asking is on and it is unclear (unknown, or an empty text): then the navigator's last
        junction answer not yet driven, else ``intent`` and an ask with this step's action."""
        if obs.answer:
            self._held = intent if intent in _HELD else None
            return intent
        if intent is not Intent.UNKNOWN and obs.instruction:
            self._held = None   # a clear instruction supersedes the navigator's answer
            return intent
        if not (self.asking and obs.instruction_id >= 0):
            return intent
        if self._held is not None:
            return self._held
        self._ask_now = True
        return intent

    def interpret(self, obs: Observation) -> Intent:
        """The maneuver the new active instruction asks for: the ``rules`` interpreter (the
        intent classifier); :class:`icrsumo.agents.llm.LLMFollower` asks a language model."""
        return classify_intent(obs.instruction) if obs.instruction else Intent.FOLLOW

    def preferred_lane(self, w: World, edge: str, lanes: tuple[int, ...], current: int) -> int:
        if self.intent in (Intent.LANE_LEFT, Intent.LANE_RIGHT) and self._instr_id not in self._lane_done:
            step = 1 if self.intent == Intent.LANE_LEFT else -1
            if self._lane_goal is None or self._lane_goal[0] != edge:
                # one lane from where the ego is, or from where an unfinished change of the
                # same side on this edge was going
                carry = self._lane_carry
                base = carry[1] if carry is not None and carry[0] == edge and \
                    (carry[1] - current) * step > 0 else current
                self._lane_goal, self._lane_carry = (edge, base + step), None
            goal = self._lane_goal[1]
            if goal == current:
                self._lane_done.add(self._instr_id)
            elif goal in lanes:
                return goal
            elif goal in self.net.passenger_lanes.get(edge, ()):
                return current  # the lane exists but does not lead on: stay
        return super().preferred_lane(w, edge, lanes, current)

    def choose(self, w: World, edge: str, options: list[str], tentative: bool) -> str | None:
        net = self.net
        if len(options) == 1:
            return options[0]
        # a junction maneuver already committed to: the instruction is used up beyond it
        intent = self.intent if self._spent in (None, edge) else Intent.FOLLOW
        ring = net.roundabout_edges
        if self._ring_named and edge not in ring:
            # "take the n-th exit of the roundabout": the ring, not a slip road past it
            into = [o for o in options if o in ring]
            if into:
                return into[0]
        if edge in ring:
            target = {Intent.RIGHT: 1, Intent.STRAIGHT: 2, Intent.LEFT: 3}.get(intent, 2)
            exits = [o for o in options if o not in ring]
            on_ring = [o for o in options if o in ring]
            if exits and (self._ring_exits + 1 >= target or not on_ring):
                if not tentative:
                    self._ring_exits = 0
                    self._commit(edge)
                return exits[0]
            if exits and not tentative:
                self._ring_exits += 1
            return on_ring[0] if on_ring else options[0]
        dirs = {o: {c.direction for c in net.connections[(edge, o)]} for o in options}
        want = {Intent.LEFT: ("l", "L"), Intent.RIGHT: ("r", "R"), Intent.STRAIGHT: ("s",)}.get(intent)
        if want:
            for d in want:
                for o in options:
                    if d in dirs[o]:
                        if not tentative and not any(n in ring for n in (o, *options)):
                            self._commit(edge)
                        return o
        for d in ("s", "L", "R", "r", "l"):
            for o in options:
                if d in dirs[o]:
                    return o
        return options[0]

    def _commit(self, edge: str) -> None:
        """The junction maneuver at the end of ``edge`` is committed to: the instruction (and a
        navigator's answer held for it) is used up beyond it."""
        self._spent = edge
        self._held = None
