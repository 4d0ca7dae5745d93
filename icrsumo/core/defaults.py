"""Names that the command line's help, the registry and the docs share, defined once (light:
no import beyond the standard library, so ``icrsumo --help`` stays fast)."""

from __future__ import annotations

#: the shipped learned agent that ``icrsumo evaluate`` uses when none is named (its text encoder
#: was trained with the training bank's paraphrases and noise); the registry falls back to the
#: instruction-follower where its checkpoint is missing
DEFAULT_AGENT = "bev-ngram-aug"
#: the suite ``evaluate`` and ``attack`` run when none is named
DEFAULT_SUITE = "tiny"
#: what an instruction a guard blocks leaves the agent (``--on-block``): ``keep``, what it was
#: shown before (the default), or ``navigator``, the navigation plan's own instruction for the
#: stretch (:mod:`icrsumo.guards.stream`)
BLOCK_POLICIES = ("keep", "navigator")
#: the version of the closed loop's rules that decide what an episode records (its events and
#: its last step); an out folder records it (``"loop"`` in config.json, absent: 1), so episodes
#: of other rules never share a table. 1: roadside once per exit, red light at the junction
#: entry, stop sign within 15 m of the lane end, the episode ending on the completing step;
#: 2: roadside contact on every step off the drivable area (CollisionTest counts it again every
#: 3 m), red light when the tail crosses the stop line (once per light), stop sign by trigger
#: volume and horizon, and the completing step followed by one more (RouteCompletionTest
#: reports success one tick later, and the other criteria count in that tick)
LOOP_VERSION = 2
