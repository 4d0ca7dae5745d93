"""Negation in a clause: what it negates, what a negation means itself ("don't move": stop),
what it only defers ("don't turn right until ..."), and alternatives that cancel ("left or
right"); :mod:`icrsumo.instructions.intent` documents the rules."""

from __future__ import annotations

from dataclasses import replace

from icrsumo.core.types import Intent

from . import lexicon as lex
from .heads import mention_at
from .records import Context, Level, Mention, followed_by, trimmed

__all__ = ["drop_alternatives", "is_negator", "negated", "negation_scope", "refers_back"]


def is_negator(c: tuple[str, ...], i: int) -> bool:
    tok = c[i]
    nxt = c[i + 1] if i + 1 < len(c) else ""
    return (
        (tok in lex.NEGATORS and not (tok == "no" and nxt in lex.NO_IDIOM))
        or (tok in ("instead", "rather") and nxt in ("of", "than"))
        or (tok == "stop" and nxt.endswith("ing") and nxt != "stopping")
    )


def negation_scope(c: tuple[str, ...]) -> tuple[list[bool], list[Mention]]:
    """Per-token negation flags and extra mentions implied by negation ("don't move" -> STOP). The
    scope ends at a driving verb after a negated mention, at a new imperative after the negated
    verb ("don't overtake here stay in your lane") and at the other side right after a negated
    side ("not right left")."""
    n = len(c)
    neg = [False] * n
    extra: list[Mention] = []
    active = seen = False
    i = start = 0
    while i < n:
        if c[i] in lex.NEGATOR_HEADS and is_negator(c, i):
            j = i + 1
            while j < n and c[j] in lex.NEG_FILLER:
                j += 1
            cancel = j < n and c[j] in lex.NEG_CANCEL  # "don't forget to turn left"
            meaning = None if cancel else _negated_meaning(c, j)
            if cancel or (meaning is None and _deferred(c, j)):  # "don't turn right until ...": later
                i, active = j + 1, False
                continue
            if meaning is not None:
                extra.append(Mention(meaning, Level.STRONG if meaning is Intent.STOP else Level.WEAK, j))
            i, active, seen, start = i + 1, True, False, j
            continue
        if active and ((c[i] in lex.DIRECTIVE and seen) or _ends_scope(c, i, start, neg)):
            active = False
        elif active:
            neg[i] = True
            seen = seen or c[i] in lex.HEADS
        i += 1
    return neg, extra


def _ends_scope(c: tuple[str, ...], i: int, start: int, neg: list[bool]) -> bool:
    """Whether token ``i`` opens what the negation at ``start`` no longer covers: a new imperative
    after the negated verb ("never mind the turn go straight"), or the other side right after a
    negated side ("no not left right"), or a new sentence ("it is ...")."""
    if c[i] in lex.LEFT_RIGHT and i and neg[i - 1] and c[i - 1] in lex.LEFT_RIGHT and c[i - 1] != c[i]:
        return True
    if i > start + 1 and c[i] in lex.THAT | {"it"} and i + 1 < len(c) and c[i + 1] in lex.COPULA:
        return True  # "don't turn yet it's the next left": a new sentence
    prev = c[i - 1]  # not what is reported: "ignore the sign saying go straight"
    given = prev not in lex.NOT_IMPERATIVE_PREV and prev not in lex.SAYING
    return i > start and c[i] in lex.SCOPE_VERBS and given


def _negated_meaning(c: tuple[str, ...], j: int) -> Intent | None:
    """What negating the phrase at ``j`` asks for: "don't move" -> STOP, "don't change lanes",
    "skip this exit" or "don't turn here" -> FOLLOW; None otherwise."""
    target = c[j] if j < len(c) else ""
    after = c[j + 1] if j + 1 < len(c) else ""
    if target in ("further", "farther") or (target in lex.NEG_MOTION and after in lex.NEG_MOTION_NEXT):
        return Intent.STOP
    lane_keep = target in ("change", "switch") and after in lex.LANE and not (lex.LEFT_RIGHT & set(c[j:]))
    lane_keep = lane_keep or (target in ("merge", "merging") and after in lex.NOT_YET)  # "don't merge yet"
    bare_turn = target == "turn" and after in ("", "here", "yet", "now", "anywhere", "at", "off")
    if target in lex.DEVIATE or (target in ("leave", "quit") and followed_by(c, j, lex.ROAD, 3)):
        return Intent.FOLLOW  # "do not deviate from this route", "don't leave the highway"
    if lane_keep or bare_turn or "exit" in c[j : j + 4] or "exits" in c[j : j + 4]:
        return Intent.FOLLOW
    return None


def _deferred(c: tuple[str, ...], j: int) -> bool:
    """Whether the maneuver negated at ``j`` is deferred, not refused: "until" / "till" follows it
    ("do not take a right turn until all cars have passed"); a negated stop stays negated."""
    return j < len(c) and c[j] not in lex.STOP_HEADS and any(t in lex.NEG_DEFER for t in c[j + 1 :])


def negated(c: tuple[str, ...], ctx: Context) -> list[Mention]:
    """The maneuvers (implied or explicit) that clause ``c`` negates ("not the first right")."""
    if not set(c) & lex.NEGATOR_HEADS:
        return []
    neg, _ = negation_scope(c)
    found = (mention_at(c, i, ctx, False, False) for i, t in enumerate(c) if neg[i] and t in lex.TRIGGERS)
    return [replace(m, at=0) for m in found if m is not None and m.level >= Level.MEDIUM]


def refers_back(c: tuple[str, ...]) -> bool:
    """A short clause naming "the second / next / other one" ("take the second"): the maneuver
    just negated, again."""
    c = trimmed(c)
    return 0 < len(c) <= 6 and (c[-1] == "one" or c[-1] in lex.BACK_REFERENCE) and any(
        t in lex.BACK_REFERENCE for t in c)


def drop_alternatives(c: tuple[str, ...], found: list[Mention]) -> list[Mention]:
    """Drop directions offered as alternatives ("turn left or right")."""
    drop: set[int] = set()
    for a, b in zip(found, found[1:]):
        gap = c[a.at + 1 : b.at]
        strong = a.level == b.level == Level.STRONG
        if a.intent != b.intent and strong and "or" in gap and all(t in lex.OR_GAP for t in gap):
            drop.update((a.at, b.at))
    return [m for m in found if m.at not in drop] if drop else found
