"""Steps 2-5 of the intent classifier and its precedence: clauses, the mentions in each (with
negation and subordination), and the choice among them. :mod:`icrsumo.instructions.intent`
documents every rule; the word lists live in :mod:`icrsumo.instructions.lexicon`."""

from __future__ import annotations

from collections.abc import Set
from dataclasses import dataclass, replace
from enum import IntEnum

from icrsumo.core.types import Intent

from . import lexicon as lex

__all__ = ["Context", "Level", "Mention", "choose", "mentions"]

#: what "... and continue straight" continues; and the maneuvers a stop or wait before them yields to
_TURNS = frozenset({Intent.LEFT, Intent.RIGHT, Intent.LANE_LEFT, Intent.LANE_RIGHT})
_MANEUVERS = _TURNS | {Intent.STRAIGHT}


class Level(IntEnum):
    """How strongly a mention asks for its intent; within a clause only the highest level survives."""

    NOTICE = 0  #: a caution notice ("stop sign ahead"): STOP when nothing else is asked
    WEAK = 1  #: FOLLOW the road
    MEDIUM = 2  #: implied: a highway exit -> RIGHT, crossing a junction -> STRAIGHT
    STRONG = 3  #: explicit: a side, straight, a lane change, stop, a roundabout exit by ordinal


@dataclass(frozen=True, slots=True)
class Mention:
    """One intent a clause asks for."""

    intent: Intent
    level: Level
    #: index in its clause of the token that heads it (0 when the whole clause is the mention)
    at: int
    #: after a subordinating word ("after turning left, ...") or in a clause opened by "otherwise"
    subordinate: bool = False


@dataclass(frozen=True, slots=True)
class Context:
    """What the whole text names: it changes how exits, "ahead" and crossings read."""

    roundabout: bool
    junction: bool
    highway: bool

    @classmethod
    def of(cls, words: Set[str]) -> Context:
        """The context of a text whose tokens are ``words``."""
        return cls(bool(words & lex.ROUNDABOUT), bool(words & lex.JUNCTION), bool(words & lex.HIGHWAY))


def _clauses(tokens: tuple[str, ...]) -> list[tuple[tuple[str, ...], str]]:
    """(tokens, opener) for each clause, in text order: the opener is the last boundary or joining
    word before it ("and", "then", "otherwise", ","; "" for the first clause)."""
    out: list[tuple[tuple[str, ...], str]] = []
    start, opener = 0, ""
    for i, tok in enumerate(tokens):
        split = tok in lex.SPLIT and not (tok in lex.NEGATOR_HEADS and _is_negator(tokens, i))
        if tok in lex.BOUNDARY or split:
            if i > start:
                out.append((tokens[start:i], opener))
            start, opener = i + 1, tok
    if start < len(tokens):
        out.append((tokens[start:], opener))
    return out


def _is_negator(c: tuple[str, ...], i: int) -> bool:
    tok = c[i]
    nxt = c[i + 1] if i + 1 < len(c) else ""
    return (
        (tok in lex.NEGATORS and not (tok == "no" and nxt in lex.NO_IDIOM))
        or (tok in ("instead", "rather") and nxt in ("of", "than"))
        or (tok == "stop" and nxt.endswith("ing") and nxt != "stopping")
    )


def _negated_meaning(c: tuple[str, ...], j: int) -> Intent | None:
    """What negating the phrase at ``j`` asks for: "don't move" -> STOP, "don't change lanes",
    "skip this exit" or "don't turn here" -> FOLLOW; None otherwise."""
    target = c[j] if j < len(c) else ""
    after = c[j + 1] if j + 1 < len(c) else ""
    if target in ("further", "farther") or (target in lex.NEG_MOTION and after in lex.NEG_MOTION_NEXT):
        return Intent.STOP
    lane_keep = target in ("change", "switch") and after in lex.LANE and not (lex.LEFT_RIGHT & set(c[j:]))
    bare_turn = target == "turn" and after in ("", "here", "yet", "now", "anywhere", "at", "off")
    if target in lex.DEVIATE or (target in ("leave", "quit") and _followed_by(c, j, lex.ROAD, 3)):
        return Intent.FOLLOW  # "do not deviate from this route", "don't leave the highway"
    if lane_keep or bare_turn or "exit" in c[j : j + 4] or "exits" in c[j : j + 4]:
        return Intent.FOLLOW
    return None


def _negation(c: tuple[str, ...]) -> tuple[list[bool], list[Mention]]:
    """Per-token negation flags and extra mentions implied by negation ("don't move" -> STOP)."""
    n = len(c)
    neg = [False] * n
    extra: list[Mention] = []
    active = seen = False
    i = 0
    while i < n:
        if c[i] in lex.NEGATOR_HEADS and _is_negator(c, i):
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
            i, active, seen = i + 1, True, False
            continue
        if active and c[i] in lex.DIRECTIVE and seen:
            active = False
        elif active:
            neg[i] = True
            seen = seen or c[i] in lex.HEADS
        i += 1
    return neg, extra


def _deferred(c: tuple[str, ...], j: int) -> bool:
    """Whether the maneuver negated at ``j`` is deferred, not refused: "until" / "till" follows it
    ("do not take a right turn until all cars have passed"); a negated stop stays negated."""
    return j < len(c) and c[j] not in lex.STOP_HEADS and any(t in lex.NEG_DEFER for t in c[j + 1 :])


def _is_direction(c: tuple[str, ...], i: int) -> bool:
    """Whether left/right at ``i`` names a direction (not "right now", "you have left")."""
    tok = c[i]
    prev = c[i - 1] if i else ""
    nxt = c[i + 1] if i + 1 < len(c) else ""
    if tok == "left":
        # "you have left"
        past = prev in lex.LEFT_NOT_DIR_PREV and not (i >= 2 and c[i - 2] in lex.PREPOSITIONS)
        return not past and nxt not in ("over", "behind", "alone", "unattended")
    if nxt == "of" and i + 2 < len(c) and c[i + 2] == "way":
        return False
    if prev in lex.DIR_PREV:
        return not (prev in lex.DIR_PREV_MOTION and nxt in lex.RIGHT_ADVERB_NEXT)  # "drive right through it"
    if prev == "all" or (prev in ("is", "are") and i >= 2 and c[i - 2] in ("that", "you", "thats")):
        return False
    if i == 0 and "ahead" in c[1:] and set(c[1:]) <= {"up", "ahead", "just"}:
        return True  # the whole clause is "Right (up) ahead."
    if nxt in lex.RIGHT_PLACE_NEXT:
        if prev in ("stay", "keep") and nxt == "at" and any(t in lex.FORK_PLACE for t in c[i + 2:i + 5]):
            return True  # "stay right at the fork / the Y-junction"
        return prev not in lex.STATIC_PREV  # "stop right at the line" vs "hda right at the junction"
    return nxt not in lex.RIGHT_INTENSIFIED


def _lane_bound(c: tuple[str, ...], i: int) -> bool:
    """Whether left/right at ``i`` qualifies a lane ("left lane", "lanes to the left")."""
    for j in range(i + 1, min(i + 4, len(c))):
        if c[j] in lex.LANE:
            return True
        if c[j] not in lex.LANE_FWD_SKIP:
            break
    for j in range(i - 1, max(i - 7, -1), -1):
        if c[j] in lex.LANE:
            return True
        if c[j] in lex.LANE_BACK_BLOCK or c[j] in lex.LEFT_RIGHT:
            return False
    return False


def _lane_verb(c: tuple[str, ...], i: int) -> bool:
    """Whether a lane verb governs left/right at ``i`` ("merge left", "stay on the right")."""
    j = i - 1
    while j >= 0 and c[j] in lex.LANE_VERB_SKIP:
        j -= 1
    if j >= 0 and c[j] in lex.LANE_VERBS:
        return True
    return i >= 3 and c[i - 1] in ("the", "your") and c[i - 2] in ("on", "in") and c[i - 3] in lex.LANE_KEEP


def _locative(c: tuple[str, ...], i: int) -> bool:
    """Whether "on (your|the) left/right" at ``i`` describes a place, not a maneuver."""
    if i < 2 or c[i - 1] not in ("your", "the") or c[i - 2] != "on":
        return i >= 1 and c[i - 1] == "on"
    k = i - 3
    while k >= 0 and c[k] in lex.LOCATIVE_SKIP:
        k -= 1
    if k < 0 or c[k] not in lex.ROADISH_BEFORE_ON:
        return True
    head = c[:k]
    return bool(lex.PASS & set(head)) or any(t in lex.LEFT_RIGHT for t in head)


def _left_right(c: tuple[str, ...], i: int, copula: bool, bend: bool) -> Intent | None:
    """Intent of left/right at ``i``, or None when it is no maneuver."""
    tok = c[i]
    if not _is_direction(c, i):
        return None
    if (i and c[i - 1] == "from") or (i >= 2 and c[i - 2] == "from" and c[i - 1] in lex.DETS):
        return None
    lane = Intent.LANE_LEFT if tok == "left" else Intent.LANE_RIGHT
    turn = Intent.LEFT if tok == "left" else Intent.RIGHT
    if ("lane" in c or "lanes" in c) and _lane_bound(c, i):
        return None if copula else lane
    nxt = c[i + 1] if i + 1 < len(c) else ""
    if nxt in lex.TURN_NOUN_NEXT or (nxt == "hand" and i + 2 < len(c) and c[i + 2] in lex.TURN_NOUN_NEXT):
        return turn
    if copula and not bend and i and (c[i - 1] in lex.COPULA or (
            nxt == "" and i >= 2 and c[i - 1] == "a" and c[i - 2] in lex.COPULA)):
        return turn  # "the only open way is left", "then it's a right"
    if copula or bend:
        return None
    if _lane_verb(c, i) or _overtakes(c, i):
        return lane
    return None if _locative(c, i) else turn


def _overtakes(c: tuple[str, ...], i: int) -> bool:
    """Whether left/right at ``i`` is the side on which the ego passes another road user ("pass
    the cyclist on the left", "go around it on the right"), a lane change."""
    on = i - 1 if i >= 1 and c[i - 1] == "on" else i - 2
    if on < 1 or c[on] != "on":
        return False
    for k in range(on - 1, max(on - 6, -1), -1):
        if c[k] in lex.OVERTAKE_VERBS:
            return any(t in lex.ROAD_USERS or t in lex.OVERTAKEN for t in c[k + 1 : on])
    return False


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


def _stop_word(c: tuple[str, ...], i: int) -> bool:
    """Whether stop/halt at ``i`` is the verb (or "come to a stop"), not "stop sign"."""
    prev = c[i - 1] if i else ""
    nxt = c[i + 1] if i + 1 < len(c) else ""
    if nxt in lex.STOP_NOUN_NEXT or prev in lex.STOP_NOUN_PREV:
        return False
    if prev in lex.STOP_ADJ:
        return any(t in lex.STOP_COME for t in c[:i])
    return True


def _followed_by(c: tuple[str, ...], i: int, words: frozenset[str], span: int = 4) -> bool:
    return any(t in words for t in c[i + 1 : i + 1 + span])


def _mention(c: tuple[str, ...], i: int, ctx: Context, copula: bool, bend: bool) -> Mention | None:
    """The mention headed by token ``i`` of clause ``c``, or None."""
    junction = ctx.junction
    tok = c[i]
    prev = c[i - 1] if i else ""
    nxt = c[i + 1] if i + 1 < len(c) else ""
    if tok in lex.LEFT_RIGHT:
        intent = _left_right(c, i, copula, bend)
        return Mention(intent, Level.STRONG, i) if intent is not None else None
    if tok == "straight":
        if (nxt == "away" and prev not in lex.MOTION) or bend or copula:
            return None
        if not junction and _along_road(c, i):  # "drive straight on this road": no junction to cross
            return Mention(Intent.FOLLOW, Level.WEAK, i)
        return Mention(Intent.STRAIGHT, Level.STRONG, i)
    if tok in lex.STOP_HEADS and _stop_mention(c, i, tok, prev, nxt):
        return Mention(Intent.STOP, Level.STRONG, i)
    if tok in lex.EXIT_HEADS or tok in lex.ORDINALS:
        return _exit_mention(c, i, tok, prev, nxt, ctx)
    if tok in lex.TRAVERSE or tok in ("cross", "crosses"):
        if _crosses_junction(c, i, junction):
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
    if k < len(c) and c[k] in lex.AT_JUNCTION and _crosses_junction(c, k, junction):
        return Mention(Intent.STRAIGHT, Level.MEDIUM, i)
    return Mention(Intent.FOLLOW, Level.WEAK, i)


def _stop_mention(c: tuple[str, ...], i: int, tok: str, prev: str, nxt: str) -> bool:
    """Whether stop/halt/brake/wait/park/pull/stand/stay/hold at ``i`` asks to stop."""
    if tok in ("stop", "stops", "stopping", "halt"):
        return _stop_word(c, i)
    if tok in ("standstill", "brake", "brakes", "braking", "wait", "waiting"):
        return nxt not in ("light", "lights")
    if tok == "park":
        return prev not in lex.DETS and (not prev or prev in lex.PARK_PREV or nxt in lex.PARK_NEXT)
    if tok == "pull":
        return nxt in lex.PULL_STOP or (nxt == "off" and not _followed_by(c, i, lex.EXIT_CONTEXT, 5))
    if tok == "hold":
        return nxt in ("still", "here", "position") or c[i + 2 : i + 3] == ("position",)
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
        if ctx.roundabout:
            k = _exit_ordinal(c, i)
            return Mention(_ordinal_intent(k), Level.STRONG, i) if k else None
        k = lex.ORDINALS.get(prev, 0)
        if k >= 2 and not ctx.highway:
            return Mention(_ordinal_intent(k), Level.STRONG, i)
        return Mention(Intent.RIGHT, Level.MEDIUM, i)
    if tok == "off" and prev in lex.OFF_VERBS and _off_at_exit(c, i):
        return Mention(Intent.RIGHT, Level.MEDIUM, i)
    if tok in lex.ORDINALS:  # "take the first (one)" at a roundabout
        if ctx.roundabout and prev == "the" and nxt in ("", "one"):
            return Mention(_ordinal_intent(lex.ORDINALS[tok]), Level.STRONG, i)
        return None
    if tok == "ramp":
        if prev == "off":
            return Mention(Intent.RIGHT, Level.MEDIUM, i)
        return Mention(Intent.FOLLOW, Level.WEAK, i)
    if _followed_by(c, i, lex.HIGHWAY, 3):  # leave / get off the motorway
        return Mention(Intent.RIGHT, Level.MEDIUM, i)
    return _follow(c, i, tok, nxt)


def _off_at_exit(c: tuple[str, ...], i: int) -> bool:
    """Whether "off" at ``i`` leaves a highway: "(come / get) off at junction 12 / the slip road"."""
    tail = c[i + 2 : i + 6] if c[i + 1 : i + 2] == ("at",) else ()
    numbered = any(t == "junction" and n.isdigit() for t, n in zip(tail, tail[1:]))
    return numbered or any(t in lex.EXIT_CONTEXT or t in lex.SLIP for t in tail)


def _crosses_junction(c: tuple[str, ...], i: int, junction: bool) -> bool:
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
        or (tok in lex.START_VERBS and _followed_by(c, i, lex.START_OBJECTS, 3))
        or (tok in lex.SET_OFF and nxt in lex.SET_OFF[tok])
        or (tok in lex.MOTION and _followed_by(c, i, lex.FOLLOW_CONTEXT, 8))
        or (tok in lex.MOTION and i == len(c) - 1 and (i == 0 or c[i - 1] in lex.BARE_MOTION_PREV))
        or (tok in lex.ROAD_VERBS and _followed_by(c, i, lex.ROAD, 3))
        or (tok == "get" and nxt in ("on", "onto") and _followed_by(c, i, lex.ROAD, 4))
    )
    return Mention(Intent.FOLLOW, Level.WEAK, i) if follow else None


def _third_party(c: tuple[str, ...]) -> bool:
    """A clause about another road user ("the black car is turning left", "a motorbike is
    changing into the right lane", "the bus in front of you will turn left"): it opens with a
    noun phrase headed by a road user, then (past a place: "ahead", "behind you", "in the left
    lane") an auxiliary or a verb of its own. Its directions ask the ego for nothing."""
    head = next((k for k in range(min(len(c), 5)) if c[k] in lex.ROAD_USERS), None)
    if head is None or (head and c[0] not in lex.DETS | lex.THIRD_DETS):
        return False
    if any(t in lex.DIRECTIVE or t in lex.LANE_VERBS for t in c[1:head]):
        return False
    k = head + 1
    while k < len(c) and c[k] in lex.PLACE_WORDS:
        k += 1
    return k < len(c) and c[k] in lex.THIRD_VERBS


def _speed_or_drop_off(c: tuple[str, ...], words: set[str]) -> Intent | None:
    """Commands that are no maneuver: driving faster ("speed up", "go faster", "accelerate",
    "pick up the pace", "put your foot down") keeps to the road (FOLLOW); being dropped off / let
    out, and letting another road user by ("let them pass"), is a STOP."""
    pick_up_pace = {"pick", "up"} <= words and words & lex.PACE
    idiom = any(i <= words for i in lex.FASTER_IDIOMS)  # "put your foot down"
    if words & lex.FASTER or ("speed" in words and "up" in words) or pick_up_pace or idiom:
        return Intent.FOLLOW
    if ("drop" in words and "off" in words) or ("let" in words and "out" in words and words & lex.US):
        return Intent.STOP
    return Intent.STOP if "let" in words and _yields(c) else None


def _yields(c: tuple[str, ...]) -> bool:
    """Letting another road user go by ("let them pass", "let the bus through"): a STOP."""
    return any(t == "let" and c[k + 1 : k + 2] != () and c[k + 1] not in lex.US
               and any(w in lex.LET_YIELD for w in c[k + 2 : k + 5]) for k, t in enumerate(c))


def _is_copular(c: tuple[str, ...], words: set[str]) -> bool:
    """A descriptive clause: a copula, no driving verb, no progressive ("the exit is on your left")."""
    if not words & lex.COPULA or words & lex.DIRECTIVE or words & lex.MODAL:
        return False
    if c[0] in lex.COPULA or c[0] == "please":
        return False
    return not any(len(t) > 5 and t.endswith("ing") and t not in lex.ING_NOUNS for t in c)


def _bends(c: tuple[str, ...]) -> bool:
    """Whether the road itself bends in this clause ("the road curves left")."""
    return any(t in lex.BEND and any(s in lex.BEND_SUBJECT for s in c[:k]) for k, t in enumerate(c))


def _clause_mentions(c: tuple[str, ...], alt: bool, ctx: Context) -> list[Mention]:
    """Surviving (non-negated, highest-level) mentions of one clause; ``alt``: the clause opens
    with "otherwise" (all its mentions are subordinate)."""
    words = set(c)
    if words & lex.ROAD_USERS and _third_party(c):  # another road user's maneuver: none of ours
        return _notice(c, words, alt)
    other = _speed_or_drop_off(c, words) if words & lex.NO_MANEUVER else None
    if other is not None:
        return [Mention(other, Level.STRONG if other is Intent.STOP else Level.WEAK, 0, alt)]
    if not words & lex.TRIGGERS_OR_NEG:
        return _notice(c, words, alt)
    neg, extra = _negation(c) if words & lex.NEGATOR_HEADS else ([False] * len(c), [])
    copula = _is_copular(c, words)
    forbidden = words & lex.PROHIBITED or (copula and words & lex.CLOSED)
    if forbidden or ("not" in words and words & lex.PERMITTED):
        return []  # "turning right is prohibited", "left turns are not allowed", "left is closed"
    bend = bool(words & lex.BEND) and _bends(c)
    found = list(extra)
    for i, tok in enumerate(c):
        if tok in lex.TRIGGERS and not neg[i]:
            m = _mention(c, i, ctx, copula, bend)
            if m is not None:
                found.append(m)
    if extra:
        found.sort(key=lambda m: m.at)
    if "or" in words:
        found = _drop_alternatives(c, found)
    if not found:
        return _notice(c, words, alt)
    top = max(m.level for m in found)
    found = [m for m in found if m.level == top]
    if not words & lex.SUBORDINATE:
        return [replace(m, subordinate=alt) for m in found]
    return _subordinate(c, found, alt)


def _notice(c: tuple[str, ...], words: set[str], alt: bool) -> list[Mention]:
    """The clause's one NOTICE-level STOP when it is a caution notice, else nothing."""
    return [Mention(Intent.STOP, Level.NOTICE, 0, alt)] if _is_notice(c, words) else []


def _is_notice(c: tuple[str, ...], words: set[str]) -> bool:
    """A caution notice ("watch out for pedestrians", "stop sign ahead", "slow down", "yield")."""
    if words & lex.CAUTION or any(pair <= words for pair in lex.CAUTION_PAIRS):
        return True  # "watch out", "give way", "heads up", "keep an eye out for cyclists"
    if "slow" in words and ("down" in words or c[0] == "slow"):
        return True
    if words & lex.DECELERATE or (words & lex.SPEED and words & lex.LESS):
        return True  # "decelerate", "drive slower", "reduce your speed", "easy on the gas"
    hazard = words & lex.HAZARD or words & lex.LIGHTS or ("stop" in words and "sign" in words)
    return bool(hazard and words & lex.APPROACH)


def _subordinate(c: tuple[str, ...], found: list[Mention], alt: bool) -> list[Mention]:
    """Mark the mentions of the clause's condition subordinate: from its subordinating word up to an
    imperative after it ("once clear turn left": the left turn is the main clause's). A stop or
    wait before a maneuver is its precondition: "wait for a gap before you turn left" is the turn."""
    start = next(k for k, t in enumerate(c) if t in lex.SUBORDINATE)
    end = next((k for k in range(start + 2, len(c)) if _imperative(c, k, start)), len(c))
    out = [replace(m, subordinate=alt or start < m.at < end) for m in found]
    main = [m for m in out if not m.subordinate]
    if alt or c[start] not in lex.DEFERRING or not main or any(m.intent is not Intent.STOP for m in main):
        return out
    return [replace(m, subordinate=False) if m.intent in _MANEUVERS else m for m in out]


def _drop_alternatives(c: tuple[str, ...], found: list[Mention]) -> list[Mention]:
    """Drop directions offered as alternatives ("turn left or right")."""
    drop: set[int] = set()
    for a, b in zip(found, found[1:]):
        gap = c[a.at + 1 : b.at]
        strong = a.level == b.level == Level.STRONG
        if a.intent != b.intent and strong and "or" in gap and all(t in lex.OR_GAP for t in gap):
            drop.update((a.at, b.at))
    return [m for m in found if m.at not in drop] if drop else found


def choose(found: list[Mention]) -> Intent:
    """The intent that mentions (in text order) ask for, by the precedence rules in
    :mod:`icrsumo.instructions.intent`."""
    pool = [m for m in found if not m.subordinate] or found
    specific = [m.intent for m in pool if m.level >= Level.MEDIUM]
    if specific:
        return specific[-1]
    if any(m.level == Level.WEAK for m in pool):
        return Intent.FOLLOW
    return Intent.STOP if pool else Intent.UNKNOWN  # only caution notices left


def _imperative(c: tuple[str, ...], k: int, start: int) -> bool:
    """Whether ``c[k]`` opens an imperative after the condition at ``start`` ("once clear turn",
    "after that head"; not "when you turn", "if you can go")."""
    that = k == start + 2 and c[start + 1] in lex.THAT
    return c[k] in lex.IMPERATIVE and (that or c[k - 1] not in lex.NOT_IMPERATIVE_PREV | lex.SUBORDINATE)


def _negated(c: tuple[str, ...], ctx: Context) -> list[Mention]:
    """The maneuvers (implied or explicit) that clause ``c`` negates ("not the first right")."""
    if not set(c) & lex.NEGATOR_HEADS:
        return []
    neg, _ = _negation(c)
    found = (_mention(c, i, ctx, False, False) for i, t in enumerate(c) if neg[i] and t in lex.TRIGGERS)
    return [replace(m, at=0) for m in found if m is not None and m.level >= Level.MEDIUM]


def _refers_back(c: tuple[str, ...]) -> bool:
    """A short clause naming "the second / next / other one": the maneuver just negated, again."""
    return len(c) <= 6 and c[-1] == "one" and any(t in lex.BACK_REFERENCE for t in c)


def _continues(c: tuple[str, ...], found: list[Mention]) -> bool:
    """Whether clause ``c`` ("continue / carry / keep straight (on)", no junction named) continues
    the turn or lane change before it rather than naming a maneuver of its own."""
    return (c[0] in lex.CONTINUATION_HEADS and "straight" in c and not set(c) & lex.JUNCTION
            and any(not m.subordinate and m.level >= Level.MEDIUM and m.intent in _TURNS for m in found))


def mentions(tokens: tuple[str, ...]) -> list[Mention]:
    """Every surviving mention of a normalized instruction, clause by clause in text order; a clause
    that only refers back ("the second one") takes the maneuver the clause before it negated, and
    "... and continue straight" after a turn is the turn's continuation (FOLLOW)."""
    ctx = Context.of(set(tokens))
    found: list[Mention] = []
    before: tuple[str, ...] = ()
    for clause, opener in _clauses(tokens):
        own = _clause_mentions(clause, opener == "otherwise", ctx)
        if not own and before and _refers_back(clause):
            own = _negated(before, ctx)[-1:]
        elif opener in lex.CONTINUATION_OPENERS and _continues(clause, found):
            own = [replace(m, intent=Intent.FOLLOW, level=Level.WEAK) if m.intent is Intent.STRAIGHT else m
                   for m in own]
        found.extend(own)
        before = clause
    return found
