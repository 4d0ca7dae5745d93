"""The intent classifier's records: a :class:`Mention` (an intent a clause asks for, at a
:class:`Level`) and the :class:`Context` a whole text sets; :mod:`icrsumo.instructions.intent`
documents the rules that make them."""

from __future__ import annotations

from collections.abc import Set
from dataclasses import dataclass
from enum import IntEnum

from icrsumo.core.types import Intent

from . import lexicon as lex

__all__ = ["MANEUVERS", "TURNS", "Context", "Level", "Mention", "followed_by", "trimmed"]

#: what "... and continue straight" continues; and the maneuvers a stop or wait before them yields to
TURNS = frozenset({Intent.LEFT, Intent.RIGHT, Intent.LANE_LEFT, Intent.LANE_RIGHT})
MANEUVERS = TURNS | {Intent.STRAIGHT}


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


def followed_by(c: tuple[str, ...], i: int, words: frozenset[str], span: int = 4) -> bool:
    return any(t in words for t in c[i + 1 : i + 1 + span])


def trimmed(c: tuple[str, ...]) -> tuple[str, ...]:
    """Clause ``c`` without the fillers at its ends ("please", "now", "ok", "thanks")."""
    a, b = 0, len(c)
    while a < b and c[a] in lex.FILLERS:
        a += 1
    while b > a and c[b - 1] in lex.FILLERS:
        b -= 1
    return c[a:b]
