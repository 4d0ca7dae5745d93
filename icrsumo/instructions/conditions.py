"""Conditions and continuations: which mentions sit in a condition ("once clear, turn left"),
and "... and continue straight" after a turn; :mod:`icrsumo.instructions.intent` documents the
rules."""

from __future__ import annotations

from dataclasses import replace

from icrsumo.core.types import Intent

from . import lexicon as lex
from .records import MANEUVERS, TURNS, Level, Mention

__all__ = ["continues", "mark_subordinate"]


def mark_subordinate(c: tuple[str, ...], found: list[Mention], alt: bool) -> list[Mention]:
    """Mark the mentions of the clause's condition subordinate: from its subordinating word up to an
    imperative after it ("once clear turn left": the left turn is the main clause's). A stop or
    wait before a maneuver is its precondition: "wait for a gap before you turn left" is the turn.
    "After that" only orders what follows ("and straight after that, a right")."""
    start = next(k for k, t in enumerate(c) if t in lex.SUBORDINATE)
    if c[start + 1 : start + 2] and c[start + 1] in lex.THAT and c[start] in lex.SEQUENCE:
        end = start + 2
    else:
        end = next((k for k in range(start + 2, len(c)) if _imperative(c, k, start)), len(c))
    out = [replace(m, subordinate=alt or start < m.at < end) for m in found]
    main = [m for m in out if not m.subordinate]
    if alt or c[start] not in lex.DEFERRING or not main or any(m.intent is not Intent.STOP for m in main):
        return out
    return [replace(m, subordinate=False) if m.intent in MANEUVERS else m for m in out]


def _imperative(c: tuple[str, ...], k: int, start: int) -> bool:
    """Whether ``c[k]`` opens an imperative after the condition at ``start`` ("once clear turn",
    "after that head"; not "when you turn", "if you can go")."""
    that = k == start + 2 and c[start + 1] in lex.THAT
    return c[k] in lex.IMPERATIVE and (that or c[k - 1] not in lex.NOT_IMPERATIVE_PREV | lex.SUBORDINATE)


def continues(c: tuple[str, ...], found: list[Mention]) -> bool:
    """Whether clause ``c`` ("continue / carry / keep straight (on)", no junction named) continues
    the turn or lane change before it rather than naming a maneuver of its own."""
    return (c[0] in lex.CONTINUATION_HEADS and "straight" in c and not set(c) & lex.JUNCTION
            and any(not m.subordinate and m.level >= Level.MEDIUM and m.intent in TURNS for m in found))
