"""What a learned agent remembers of the active instruction: the maneuver it has already driven
and how far it has come since the instruction arrived (issue 47).

The networks see one frame: the BEV raster, the speed, the stopped time and the active text. A
turn instruction stays active past its junction until the next one arrives, and a distance
instruction ("in 80 meters, turn left") names a junction that may not be the first one ahead.
Without memory, both read as "turn at the junction in view": the shipped agents left the route
on 13 of carla-fidelity's 104 baseline routes, 4 of them by turning at a junction before the
named one and 1 by turning again under a left-turn instruction 450 m past its junction.
:class:`InstructionMemory` carries, per instruction, what the agent's own sensors tell it (the
compass, :attr:`icrsumo.agents.base.Observation.compass`, and the speed integrated over the
control step: an odometer) and decides which text the network reads:

* **used up**: a left (right) turn instruction once the heading has turned by
  :data:`TURN_DONE_RAD` to the left (right) since it arrived, a lane-change instruction once the
  ego has moved :data:`LANE_DONE_M` sideways to that side (the speed integrated across the
  heading the instruction arrived at) and heads within :data:`SETTLED_RAD` of that heading
  again; in both cases the heading must then hold within :data:`SETTLED_RAD` over
  :data:`SETTLED_M` of driving (the maneuver is over: a sharp turn is not cut short at 60
  degrees, a lane change not left half-way). From then on the network reads
  :data:`FOLLOW_TEXT`, as a driver who has done the turn drives on.
* **held**: a junction instruction (left, right, straight) that names a distance is read as
  :data:`FOLLOW_TEXT` until the odometer is within :data:`HOLD_MARGIN_M` of that distance, so
  the junctions before the named one are driven by the road.

Which maneuver a text asks for is :func:`icrsumo.instructions.intent.classify_intent`'s reading
(the same for every agent; texts it reads as unknown, stop or follow are never used up or
held), and the distance is the first number followed by a unit of metres. Roundabout
instructions are passed through unchanged (the heading turns both ways in a ring). A new
instruction (another id, or the navigator's answer) starts the memory afresh. The network
itself is trained as before: the memory chooses its input text and nothing else.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from icrsumo.agents.base import Observation
from icrsumo.core.angles import wrap_angle
from icrsumo.core.vocab import Intent
from icrsumo.instructions.intent import classify_intent

#: the text the network reads once an instruction is used up, or while it is held
FOLLOW_TEXT = "Follow the road."
#: heading change (rad) after which a turn instruction is used up
TURN_DONE_RAD = math.radians(60.0)
#: sideways distance (m) after which a lane-change instruction is used up
LANE_DONE_M = 2.5
#: the heading holding within this (rad) ...
SETTLED_RAD = math.radians(5.0)
#: ... over this distance (m) ends a maneuver
SETTLED_M = 8.0
#: a distance instruction is shown from this many metres before its named distance
HOLD_MARGIN_M = 15.0

_DISTANCE = re.compile(r"(\d+(?:\.\d+)?)\s*(?:m|meters?|metres?)\b", re.IGNORECASE)
_RING = re.compile(r"roundabout|traffic circle|rotary|\bcircle\b", re.IGNORECASE)
_JUNCTION = (Intent.LEFT, Intent.RIGHT, Intent.STRAIGHT)


def stated_distance(text: str) -> float | None:
    """The first distance in metres ``text`` names (``"in 80 meters"`` -> 80.0), else None."""
    m = _DISTANCE.search(text)
    return float(m.group(1)) if m else None


@dataclass
class InstructionMemory:
    """One episode's memory of its active instruction (mutable; one per agent and episode).
    :meth:`text` is called once per control step, ``dt`` s apart, with that step's observation
    and returns the text the network reads."""

    key: tuple[int, bool] | None = None
    intent: Intent = Intent.FOLLOW
    distance: float | None = None
    heading0: float = 0.0
    odometer: float = 0.0      # m driven since the instruction arrived
    lateral: float = 0.0       # m moved to the left of the heading it arrived at
    done: bool = False         # the maneuver has been driven far enough ...
    steady: tuple[float, float] | None = None   # ... and the heading (rad) and odometer (m)
    used_up: bool = False                       # since which it has held

    def text(self, obs: Observation, dt: float) -> str:
        key = (obs.instruction_id, obs.answer)
        if key != self.key:
            text = obs.instruction
            ring = bool(_RING.search(text))
            self.key = key
            self.intent = classify_intent(text) if text and not ring else Intent.FOLLOW
            self.distance = stated_distance(text) if self.intent in _JUNCTION else None
            self.heading0, self.odometer, self.lateral = obs.compass, 0.0, 0.0
            self.done, self.steady, self.used_up = False, None, False
        turned = wrap_angle(obs.compass - self.heading0)   # > 0: turned left
        step = max(obs.speed, 0.0) * dt
        self.odometer += step
        self.lateral += step * math.sin(turned)
        intent, parallel = self.intent, abs(turned) <= SETTLED_RAD
        if (intent is Intent.LEFT and turned >= TURN_DONE_RAD) or \
                (intent is Intent.RIGHT and turned <= -TURN_DONE_RAD) or \
                (intent is Intent.LANE_LEFT and self.lateral >= LANE_DONE_M and parallel) or \
                (intent is Intent.LANE_RIGHT and self.lateral <= -LANE_DONE_M and parallel):
            self.done = True
        if self.done and not self.used_up:
            if self.steady is None or abs(wrap_angle(obs.compass - self.steady[0])) > SETTLED_RAD:
                self.steady = (obs.compass, self.odometer)
            self.used_up = self.odometer - self.steady[1] >= SETTLED_M
        held = self.distance is not None and self.odometer < self.distance - HOLD_MARGIN_M
        return FOLLOW_TEXT if self.used_up or held else obs.instruction
