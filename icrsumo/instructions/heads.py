"""The mention one token heads: a side, straight on, a stop, an exit or ramp, a crossing, keeping
one's course or following the road; :mod:`icrsumo.instructions.intent` documents the rules."""

from __future__ import annotations

from icrsumo.core.types import Intent

from . import lexicon as lex
from .records import Context, Level, Mention, followed_by
from .sides import left_right

__all__ = ["crosses_junction", "mention_at"]


def mention_at(c: tuple[str, ...], i: int, ctx: Context, copula: bool, bend: bool) -> Mention | None:
    """The mention headed by token ``i`` of clause ``c``, or None."""
    junction = ctx.junction
    tok = c[i]
    prev = c[i - 1] if i else ""
    nxt = c[i + 1] if i + 1 < len(c) else ""
    if tok in lex.LEFT_RIGHT:
        intent = left_right(c, i, copula, bend)
        return Mention(intent, Level.STRONG, i) if intent is not None else None
    if tok == "straight":
        at_once = (nxt == "away" and prev not in lex.MOTION) or (nxt in lex.STRAIGHT_AFTER and not prev)
        if at_once or bend or copula:  # "straight away", "(and) straight after that, a right"
            return None
        if not junction and _along_road(c, i):  # "drive straight on this road": no junction to cross
            return Mention(Intent.FOLLOW, Level.WEAK, i)
        return Mention(Intent.STRAIGHT, Level.STRONG, i)
    if tok in lex.STOP_HEADS and _stop_mention(c, i, tok, prev, nxt):
        return Mention(Intent.STOP, Level.STRONG, i)
    if tok in lex.EXIT_HEADS or tok in lex.ORDINALS:
        return _exit_mention(c, i, tok, prev, nxt, ctx)
    if tok in lex.TRAVERSE or tok in ("cross", "crosses"):
        if crosses_junction(c, i, junction):
            return Mention(Intent.STRAIGHT, Level.MEDIUM, i)
    elif tok == "ahead":
        if not any(t in lex.AHEAD_VERBS for t in c[max(0, i - 2) : i]):
            return None
        if junction:
            return Mention(Intent.STRAIGHT, Level.MEDIUM, i)
        return Mention(Intent.FOLLOW, Level.WEAK, i)
    if tok in lex.COURSE_KEEP:
        kept = _course(c, i, junction)
        if kept is not None:
            return kept
    return _follow(c, i, tok, nxt)


def _along_road(c: tuple[str, ...], i: int) -> bool:
    """Whether "straight" at ``i`` runs along a road ("straight on this road", "straight down
    the highway") rather than across a junction."""
    return i + 1 < len(c) and c[i + 1] in ("on", "along", "down", "up") and any(
        t in lex.ROAD for t in c[i + 2 : i + 5])


def _course(c: tuple[str, ...], i: int, junction: bool) -> Mention | None:
    """Keeping one's course at ``i`` ("maintain your course", "hold your current heading"):
    STRAIGHT when it is kept at / through a junction, else FOLLOW; None when no course noun
    follows."""
    j = i + 1
    while j < len(c) and j <= i + 3 and c[j] in lex.COURSE_SKIP:
        j += 1
    if j >= len(c) or c[j] not in lex.COURSE:
        return None
    k = j + 2 if j + 1 < len(c) and c[j + 1] == "straight" else j + 1
    if k < len(c) and c[k] in lex.AT_JUNCTION and crosses_junction(c, k, junction):
        return Mention(Intent.STRAIGHT, Level.MEDIUM, i)
    return Mention(Intent.FOLLOW, Level.WEAK, i)


def _stop_word(c: tuple[str, ...], i: int) -> bool:
    """Whether stop/halt at ``i`` is the verb (or "come to a stop"), not "stop sign"."""
    prev = c[i - 1] if i else ""
    nxt = c[i + 1] if i + 1 < len(c) else ""
    if nxt in lex.STOP_NOUN_NEXT or prev in lex.STOP_NOUN_PREV:
        return False
    if prev in lex.STOP_ADJ:
        return any(t in lex.STOP_COME for t in c[:i])
    return True


def _stop_mention(c: tuple[str, ...], i: int, tok: str, prev: str, nxt: str) -> bool:
    """Whether stop/halt/brake/wait/park/pull/stand/stay/hold at ``i`` asks to stop."""
    if tok in ("stop", "stops", "stopping", "halt"):
        return _stop_word(c, i)
    if tok in ("standstill", "brake", "brakes", "braking", "wait", "waiting"):
        return nxt not in ("light", "lights")
    if tok == "park":
        return prev not in lex.DETS and (not prev or prev in lex.PARK_PREV or nxt in lex.PARK_NEXT)
    if tok == "pull":
        return nxt in lex.PULL_STOP or (nxt == "off" and not followed_by(c, i, lex.EXIT_CONTEXT, 5))
    if tok == "hold":
        return nxt in ("still", "here", "position", "it") or c[i + 2 : i + 3] == ("position",)
    return (tok == "stand" and nxt == "still") or (tok == "stay" and nxt in ("put", "still"))


def _exit_mention(c: tuple[str, ...], i: int, tok: str, prev: str, nxt: str, ctx: Context) -> Mention | None:
    """Exits, ramps and leaving a highway: roundabout ordinals, else an implied RIGHT. An exit
    counted by an ordinal word in a text that names no highway ("Second exit.") is read as a
    roundabout exit; highway exits go by number ("exit 23B") or by "next"."""
    if tok in ("exit", "exits"):
        j = i + 1
        while j < len(c) and c[j] in lex.DETS:
            j += 1
        if j < len(c) and c[j] in lex.NOT_ROAD_EXIT:  # "exit the parking lot"
            return None
        if _passed(c, i):  # "stay on the motorway past this exit"
            return None
        if ctx.roundabout:
            k = _exit_ordinal(c, i)
            return Mention(_ordinal_intent(k), Level.STRONG, i) if k else None
        k = lex.ORDINALS.get(prev, 0)
        if k >= 2 and not ctx.highway:
            return Mention(_ordinal_intent(k), Level.STRONG, i)
        return Mention(Intent.RIGHT, Level.MEDIUM, i)
    if tok == "off" and prev in lex.OFF_VERBS and _off_at_exit(c, i):
        return Mention(Intent.RIGHT, Level.MEDIUM, i)
    if tok in lex.ORDINALS:  # "take the first (one / turning / opportunity)" at a roundabout
        if ctx.roundabout and prev == "the" and (nxt == "" or nxt in lex.EXIT_NOUNS):
            return Mention(_ordinal_intent(lex.ORDINALS[tok]), Level.STRONG, i)
        return None
    if tok == "ramp":
        if prev == "off":
            return Mention(Intent.RIGHT, Level.MEDIUM, i)
        return Mention(Intent.FOLLOW, Level.WEAK, i)
    if followed_by(c, i, lex.HIGHWAY, 3):  # leave / get off the motorway
        return Mention(Intent.RIGHT, Level.MEDIUM, i)
    return _follow(c, i, tok, nxt)


def _exit_ordinal(c: tuple[str, ...], i: int) -> int | None:
    """Ordinal of the exit word at ``i`` ("third exit", "exit 2", "exit number two")."""
    for j in (i - 1, i - 2):
        if j >= 0 and c[j] in lex.ORDINALS:
            return lex.ORDINALS[c[j]]
    j = i + 1
    if j < len(c) and c[j] == "number":
        j += 1
    if j < len(c):
        if c[j] in lex.NUMBER_WORDS:
            return lex.NUMBER_WORDS[c[j]]
        if c[j].isdigit() and 0 < int(c[j]) < 10:
            return int(c[j])
    # "exit at the second (one / opportunity)", "exit the roundabout by the third"
    for j in range(i + 2, min(i + 7, len(c))):
        if c[j] in lex.ORDINALS and c[j - 1] == "the" and (j == i + 2 or c[j - 2] in lex.EXIT_BY):
            return lex.ORDINALS[c[j]]
    return None


def _ordinal_intent(k: int) -> Intent:
    return Intent.RIGHT if k == 1 else Intent.STRAIGHT if k == 2 else Intent.LEFT


def _passed(c: tuple[str, ...], i: int) -> bool:
    """Whether the exit at ``i`` is driven past ("past this exit", "beyond the next exit")."""
    k = i - 1
    while k >= 0 and c[k] in lex.DETS:
        k -= 1
    return k >= 0 and c[k] in lex.PASSED


def _off_at_exit(c: tuple[str, ...], i: int) -> bool:
    """Whether "off" at ``i`` leaves a highway: "(come / get) off at junction 12 / the slip road"."""
    tail = c[i + 2 : i + 6] if c[i + 1 : i + 2] == ("at",) else ()
    numbered = any(t == "junction" and n.isdigit() for t, n in zip(tail, tail[1:]))
    numbered = numbered or tail[:2] == ("the", "next") and "junction" in tail  # "at the next junction"
    return numbered or any(t in lex.EXIT_CONTEXT or t in lex.SLIP for t in tail)


def crosses_junction(c: tuple[str, ...], i: int, junction: bool) -> bool:
    """Whether ``c[i]`` crosses a junction ("through the junction", "cross it", "go through it")."""
    skip = lex.TRAVERSE_SKIP if c[i] in lex.TRAVERSE else lex.CROSS_SKIP
    j = i + 1
    while j < len(c) and c[j] in skip:
        j += 1
    return j < len(c) and (c[j] in lex.JUNCTION or (c[j] == "it" and junction))


def _follow(c: tuple[str, ...], i: int, tok: str, nxt: str) -> Mention | None:
    """FOLLOW mentions: follow/continue/keep going/stay on/merge onto/motion along a road, and
    starting to drive (start/begin/commence driving, set off, get moving, pull away, press on)."""
    if tok == "heads" and nxt == "up":  # "heads up": a warning, not a motion
        return None
    follow = (
        tok in lex.FOLLOW_VERBS
        or tok in ("merge", "merging", "resume")
        or (tok == "carry" and nxt == "on")
        or (tok in ("keep", "keeps") and nxt in lex.KEEP_NEXT)
        or (tok in ("stay", "stays", "remain", "remains", "maintain") and nxt in lex.STAY_NEXT)
        or (tok == "stick" and nxt in ("to", "with"))
        or (tok in ("start", "begin") and nxt in ("driving", "moving", "going"))
        or (tok in lex.START_VERBS and followed_by(c, i, lex.START_OBJECTS, 3))
        or (tok in lex.SET_OFF and nxt in lex.SET_OFF[tok])
        or (tok in lex.MOTION and followed_by(c, i, lex.FOLLOW_CONTEXT, 8))
        or (tok in lex.MOTION and all(t in lex.FILLERS for t in c[i + 1 :])
            and (i == 0 or c[i - 1] in lex.BARE_MOTION_PREV))
        or (tok in lex.ROAD_VERBS and followed_by(c, i, lex.ROAD, 3))
        or (tok == "get" and nxt in ("on", "onto") and followed_by(c, i, lex.ROAD, 4))
    )
    return Mention(Intent.FOLLOW, Level.WEAK, i) if follow else None
