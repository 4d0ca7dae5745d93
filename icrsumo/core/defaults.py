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
