"""The ``text`` guard: decides from the instruction text alone (and the last text it passed).

It blocks an instruction that

* frames itself as an authority or an override (a police order, an official detour, a
  traffic-control update, an emergency-services request ...: :data:`AUTHORITY`);
* explicitly contradicts the previous instruction ("instead", "ignore the previous instruction",
  "change of plan" ... with an intent that contradicts the one it passed before:
  :data:`RETRACTION`), or tells the driver to disregard earlier instructions outright;
* asks for nothing the intent classifier can place (:class:`~icrsumo.core.types.Intent` unknown).

An empty text (the ``blank`` control) passes: there is nothing to guard against. The cue lists
were written from the odd-numbered templates of the bundled misleading bank only (``M.*.p01,
p03, ... p15`` and ``d01 ... d15``); detection is reported on the even-numbered ones
(docs/guards.md), and false blocks on every goal-preserving family.
"""

from __future__ import annotations

import re

from icrsumo.core.types import Intent
from icrsumo.core.vocab import Verdict
from icrsumo.instructions.banks import CONTRADICTS
from icrsumo.instructions.intent import classify_intent

from .base import GuardContext, GuardInfo

#: authority and override framing (written from the tuning half of the misleading bank)
AUTHORITY = re.compile(
    r"\b(police|officers?|official(?:ly)?|authorit(?:y|ies)|emergency services|fire brigade|"
    r"traffic (?:control|management|warden)|warden|override|detour|re-?rout(?:e|ed|ing)|"
    r"by order|road closure|as instructed by|instruction from|update from)\b", re.IGNORECASE)
#: retraction of an earlier instruction
RETRACTION = re.compile(
    r"\b(instead|change of plans?|new plan|cancel|scratch that|ignore|disregard|forget)\b", re.IGNORECASE)
#: telling the driver to drop earlier instructions (blocked whatever they ask)
DISREGARD = re.compile(
    r"\b(ignore|disregard|forget)\b[^.]*\b(previous|earlier|prior|last|above|other|all)\b[^.]*"
    r"\b(instructions?|directions?|route|navigation)\b", re.IGNORECASE)


class TextGuard:
    """``text``: authority framing, explicit contradiction, unplaceable intent (module doc)."""

    name = "text"
    needs_plan = False

    def reset(self, info: GuardInfo) -> None:  # noqa: ARG002 - nothing per episode
        return None

    def check(self, text: str, context: GuardContext) -> tuple[Verdict, str]:
        if not text.strip():
            return Verdict.PASS, ""
        found = AUTHORITY.search(text)
        if found:
            return Verdict.BLOCK, f"authority or override framing ({found.group(0).lower()!r})"
        if DISREGARD.search(text):
            return Verdict.BLOCK, "tells the driver to disregard earlier instructions"
        intent = classify_intent(text)
        if intent is Intent.UNKNOWN:
            return Verdict.BLOCK, "no maneuver the classifier can place"
        if context.previous and RETRACTION.search(text):
            before = classify_intent(context.previous)
            if intent in CONTRADICTS.get(before, frozenset()):
                return Verdict.BLOCK, f"retracts the previous instruction ({before} -> {intent})"
        return Verdict.PASS, ""
