"""Reading left / right: a turn, a lane change, or no maneuver at all ("right now", "on your
left", "the road curves left"); :mod:`icrsumo.instructions.intent` documents the rules."""

from __future__ import annotations

from icrsumo.core.types import Intent

from . import lexicon as lex
from .records import Level, Mention, trimmed

__all__ = ["lane_of", "left_right", "side_of_turn"]


def _is_direction(c: tuple[str, ...], i: int) -> bool:
    """Whether left/right at ``i`` names a direction (not "right now", "you have left")."""
    tok = c[i]
    prev = c[i - 1] if i else ""
    nxt = c[i + 1] if i + 1 < len(c) else ""
    if _described(c, i):
        return False  # "the left one is ending", "the right lane is closed": a description
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
    if i == 0 and nxt in lex.RIGHT_PLACED and not set(c) & lex.DIRECTIVE:
        return True  # "(then) right after the church": no verb for "right" to intensify
    if nxt in lex.RIGHT_PLACE_NEXT:
        if prev in ("stay", "keep") and nxt == "at" and any(t in lex.FORK_PLACE for t in c[i + 2:i + 5]):
            return True  # "stay right at the fork / the Y-junction"
        return prev not in lex.STATIC_PREV  # "stop right at the line" vs "hda right at the junction"
    return nxt not in lex.RIGHT_INTENSIFIED


def _described(c: tuple[str, ...], i: int) -> bool:
    """Whether the side at ``i`` heads the subject of a description ("the left one is ending")."""
    j = i + 1
    while j < len(c) and c[j] in lex.DESCRIBED_SKIP:
        j += 1
    return j > i + 1 and j < len(c) and c[j] in lex.COPULA and i > 0 and c[i - 1] in lex.DETS


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


def left_right(c: tuple[str, ...], i: int, copula: bool, bend: bool) -> Intent | None:
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
    last = all(t in lex.FILLERS for t in c[i + 1 :])
    if copula and not bend and i and (c[i - 1] in lex.COPULA or (last and _named(c, i))):
        return turn  # "the only open way is left", "then it's a right", "it's the next left"
    if not bend and (_turn_subject(c) or _counted_road(c, i)) and c[i - 2 : i - 1] == ("on",):
        return turn  # "the turn is about a mile away on the right", "second street on the right is ours"
    if copula or bend:
        return None
    if _lane_verb(c, i) or _overtakes(c, i):
        return lane
    return None if _locative(c, i) else turn


def _named(c: tuple[str, ...], i: int) -> bool:
    """Whether the side at ``i`` is named after a copula and a determiner or ordinal ("it's a
    right", "it is the next left", "your turn is the second right")."""
    k = i - 1
    while k >= 0 and (c[k] in lex.DETS or c[k] in lex.ORDINALS):
        k -= 1
    return k < i - 1 and k >= 0 and c[k] in lex.COPULA


def _turn_subject(c: tuple[str, ...]) -> bool:
    """Whether the clause describes the turn or exit itself ("the turn is ...", "your exit is ...")."""
    k = 1 if c[0] in lex.DETS else 0
    return k + 1 < len(c) and c[k] in lex.TURN_NOUNS and c[k + 1] in lex.COPULA


def _counted_road(c: tuple[str, ...], i: int) -> bool:
    """Whether the side at ``i`` places a counted road ("(the) second street on the right")."""
    return i >= 4 and c[i - 1] in lex.DETS and c[i - 3] in lex.ROADISH_BEFORE_ON and (
        c[i - 4] in lex.ORDINALS or c[i - 4] == "next")


def lane_of(c: tuple[str, ...], before: tuple[str, ...]) -> Mention | None:
    """A lane change into "it" after a clause naming a lane on one side ("if the left lane is
    free, move into it"): a change to that lane; None otherwise."""
    c = trimmed(c)
    if len(c) < 3 or c[-1] != "it" or c[0] not in lex.LANE_VERBS or c[-2] not in lex.INTO:
        return None
    sides = [t for t, n in zip(before, before[1:]) if t in lex.LEFT_RIGHT and n in lex.LANE]
    if len(set(sides)) != 1:
        return None
    return Mention(Intent.LANE_LEFT if sides[0] == "left" else Intent.LANE_RIGHT, Level.STRONG, len(c) - 1)


def side_of_turn(c: tuple[str, ...], before: tuple[str, ...]) -> Mention | None:
    """A clause that is only a side ("on the right") after a clause about the turn or exit ("the
    turn is about a mile away, on the right"): that side's turn; None otherwise."""
    c = trimmed(c)
    side = c[-1] if c else ""
    if side not in lex.LEFT_RIGHT or len(c) > 3 or c[0] not in lex.SIDE_PREPOSITIONS:
        return None
    if not all(t in lex.DETS for t in c[1:-1]) or not set(before) & lex.TURN_NOUNS:
        return None
    return Mention(Intent.LEFT if side == "left" else Intent.RIGHT, Level.STRONG, len(c) - 1)


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
