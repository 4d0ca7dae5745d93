"""Clauses that ask the ego for no maneuver: another road user's maneuver, speed and drop-off
commands, letting someone by, and caution notices; :mod:`icrsumo.instructions.intent` documents
the rules."""

from __future__ import annotations

from icrsumo.core.types import Intent

from . import lexicon as lex
from .records import Level, Mention, trimmed

__all__ = ["ego_part", "notice", "speed_or_drop_off", "third_party", "yields"]


def third_party(c: tuple[str, ...]) -> bool:
    """A clause about another road user ("the black car is turning left", "a motorbike is
    changing into the right lane", "the bus in front of you will turn left"): it opens with a
    noun phrase headed by a road user, then (past a place: "ahead", "behind you", "in the left
    lane") an auxiliary or a verb of its own. Its directions ask the ego for nothing."""
    c = trimmed(c)
    head = next((k for k in range(min(len(c), 5)) if c[k] in lex.ROAD_USERS), None)
    if head is None or (head and c[0] not in lex.DETS | lex.THIRD_DETS):
        return False
    if any(t in lex.DIRECTIVE or t in lex.LANE_VERBS for t in c[1:head]):
        return False
    return _third_verb(c, head) is not None


def _third_verb(c: tuple[str, ...], head: int) -> int | None:
    """Index of the road user's own verb after its head noun at ``head`` (past a place), or None."""
    k = head + 1
    while k < len(c) and c[k] in lex.PLACE_WORDS:
        k += 1
    return k if k < len(c) and c[k] in lex.THIRD_VERBS else None


def ego_part(c: tuple[str, ...]) -> int | None:
    """Where a clause about another road user turns to the ego when no punctuation marks it: a
    condition or an imperative after the road user's verb ("the red car is reversing out wait",
    "the bus is turning left once it is gone go straight"), or "you / we" and a verb ("... you
    turn right"); None when the whole clause is about the road user."""
    head = next((k for k in range(len(c)) if c[k] in lex.ROAD_USERS), None)
    verb = _third_verb(c, head) if head is not None else None
    for m in range(verb + 1 if verb is not None else len(c), len(c)):
        tok, prev, nxt = c[m], c[m - 1], c[m + 1] if m + 1 < len(c) else ""
        if tok in lex.SUBORDINATE or (tok in lex.EGO_SUBJECTS and nxt in lex.IMPERATIVE):
            return m
        if tok == "do" and nxt == "not":
            return m
        if tok in lex.EGO_VERBS and prev not in lex.NOT_IMPERATIVE_PREV | lex.STOP_NOUN_PREV | lex.ROAD_USERS:
            return m
    return None


def speed_or_drop_off(c: tuple[str, ...], words: set[str]) -> Intent | None:
    """Commands that are no maneuver: driving faster ("speed up", "go faster", "accelerate",
    "pick up the pace", "put your foot down") keeps to the road (FOLLOW); being dropped off / let
    out ("drop me at the corner") is a STOP."""
    pick_up_pace = {"pick", "up"} <= words and words & lex.PACE
    idiom = any(i <= words for i in lex.FASTER_IDIOMS)  # "put your foot down", "floor it", "hurry up"
    speed_thing = any(t == "speed" and n in lex.SPEED_THINGS for t, n in zip(c, c[1:]))
    speed_up = "speed" in words and "up" in words and not speed_thing  # not "a speed bump coming up"
    if words & lex.FASTER or speed_up or pick_up_pace or idiom or c[0] == "hurry":  # "hurry, we're late"
        return Intent.FOLLOW
    drop = "drop" in words and ("off" in words or bool(words & lex.US))  # "drop me at the corner"
    if drop or ("let" in words and words & lex.LET_OUT and words & lex.US):  # "let me out / off here"
        return Intent.STOP
    return None


def yields(c: tuple[str, ...]) -> Mention | None:
    """Letting another road user go by ("let them pass", "let the bus through", "let it go
    first", "let it in"): a STOP at "let", which a maneuver after it may still follow ("let the
    bus pass before you turn left")."""
    k = next((k for k, t in enumerate(c) if t == "let" and c[k + 1 : k + 2] != () and c[k + 1] not in lex.US
              and (any(w in lex.LET_YIELD for w in c[k + 2 : k + 5]) or c[k + 2 : k + 3] == ("in",))), None)
    return Mention(Intent.STOP, Level.STRONG, k) if k is not None else None


def notice(c: tuple[str, ...], words: set[str], alt: bool) -> list[Mention]:
    """The clause's one NOTICE-level STOP when it is a caution notice, else nothing."""
    return [Mention(Intent.STOP, Level.NOTICE, 0, alt)] if _is_notice(c, words) else []


def _is_notice(c: tuple[str, ...], words: set[str]) -> bool:
    """A caution notice ("watch out for pedestrians", "stop sign ahead", "slow down", "yield")."""
    if words & lex.CAUTION or any(pair <= words for pair in lex.CAUTION_PAIRS):
        return True  # "watch out", "give way", "heads up", "keep an eye out for cyclists"
    if "slow" in words and not any(t == "slow" and n in lex.LANE for t, n in zip(c, c[1:])):
        return True  # "slow down", "take it slow" (not "the slow lane")
    if {"too", "fast"} <= words or ("ease" in words and words & lex.EASE_OFF):
        return True  # "you're going too fast", "ease off"
    if words & lex.DECELERATE or (words & lex.SPEED and words & lex.LESS):
        return True  # "decelerate", "drive slower", "reduce your speed", "easy on the gas"
    hazard = words & lex.HAZARD or words & lex.LIGHTS or ("stop" in words and "sign" in words)
    return bool(hazard and words & lex.APPROACH)
