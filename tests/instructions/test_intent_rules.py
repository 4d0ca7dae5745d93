"""The intent classifier's mentions as typed records (icrsumo.instructions.rules)."""

from __future__ import annotations

import dataclasses

import pytest

from icrsumo.core.types import Intent
from icrsumo.instructions.intent import classify_intent
from icrsumo.instructions.rules import Level, Mention, choose, mentions
from icrsumo.instructions.spelling import tokens


@pytest.mark.parametrize(("text", "expected"), [
    # a subordinate mention and the main clause's (the token index is within its clause)
    ("After turning left, go straight", [Mention(Intent.LEFT, Level.STRONG, 2, subordinate=True),
                                         Mention(Intent.STRAIGHT, Level.STRONG, 1)]),
    ("Take exit 23B", [Mention(Intent.RIGHT, Level.MEDIUM, 1)]),
    ("Take the third exit at the roundabout", [Mention(Intent.LEFT, Level.STRONG, 3)]),
    ("Don't move until the light turns green", [Mention(Intent.STOP, Level.STRONG, 2)]),
    ("Watch out for pedestrians", [Mention(Intent.STOP, Level.NOTICE, 0)]),
    ("Turn left or right", []),  # alternatives cancel each other
])
def test_mentions_are_records(text: str, expected: list[Mention]) -> None:
    found = mentions(tokens(text))
    assert found == expected
    assert choose(found) is classify_intent(text)


def test_mention_is_frozen() -> None:
    m = Mention(Intent.LEFT, Level.STRONG, 0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.level = Level.WEAK  # type: ignore[misc]
