"""The classifier's second round on commands as people say them (issue 45; docs/guards.md:
*Commands as people say them*).

The 399 commands of ``tuning.jsonl`` and ``held_out.jsonl`` became tuning data; a new set,
``held_out_2.jsonl``, was written before any rule of this round changed and read by the
classifier once, after the round: 246 of 269. Its misses then became tuning data for a third
round, and ``held_out_3.jsonl``, written before that round changed anything, was read once
after it: 225 of 237; its misses were fixed afterwards. Typos are checked with the Noise
family's own operations on the tuning commands (seeded), and the spelling correction's cheap
bound with an exhaustive search."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from icrsumo.core.types import Intent
from icrsumo.instructions import lexicon as lex
from icrsumo.instructions import noise
from icrsumo.instructions.intent import classify_intent
from icrsumo.instructions.spelling import _budget, _fuzzy, _neighbour_slip, _osa, _raw_words

COMMANDS = Path(__file__).parents[1] / "data" / "commands"
#: the typo operations of the Noise family, and the seeds of the typos checked
TYPOS = ("neighbour", "transpose", "delete", "insert", "double")
SEEDS = (1000, 1001, 1002, 1003)


def _read(name: str) -> list[dict[str, str]]:
    return [json.loads(line) for line in (COMMANDS / f"{name}.jsonl").read_text("utf-8").splitlines()]


TUNING = _read("tuning") + _read("held_out")
HELD_OUT_2, HELD_OUT_3 = _read("held_out_2"), _read("held_out_3")
BANK = json.loads((COMMANDS / "bank_classes.json").read_text("utf-8"))["classes"]


def _key(text: str) -> str:
    return text.lower().strip(" .!?")


def _right(items: list[dict[str, str]]) -> int:
    return sum(classify_intent(i["text"]).value == i["label"] for i in items)


def test_the_third_held_out_set_is_new() -> None:
    earlier = {_key(t) for t in BANK} | {_key(i["text"]) for i in TUNING + HELD_OUT_2}
    texts = [_key(i["text"]) for i in HELD_OUT_3]
    assert not [t for t in texts if t in earlier] and len(set(texts)) == len(texts) >= 200
    assert {i["category"] for i in HELD_OUT_3} == {i["category"] for i in TUNING}
    assert {i["label"] for i in HELD_OUT_3} == {i.value for i in Intent}
    for item in HELD_OUT_3:
        assert set(item) == {"text", "label", "category"} and item["text"].strip()


def test_second_held_out_set() -> None:
    # 244 of 269 (90.7 %) before the second round, 246 (91.4 %) after it, read once; all after
    # the third round, which was tuned on its misses (so that number says little)
    assert _right(HELD_OUT_2) == len(HELD_OUT_2) == 269


def test_third_held_out_set() -> None:
    # 223 of 237 (94.1 %) before the second round, 225 (94.9 %) after the third, read once; all
    # after its twelve misses were fixed too (so that number says little)
    assert _right(HELD_OUT_3) == len(HELD_OUT_3) == 237


def _typo_variants() -> list[tuple[str, str]]:
    """(text, label): every tuning command under each typo operation, once per seed."""
    out = []
    for seed in SEEDS:
        rng = np.random.default_rng(seed)
        for item in TUNING:
            out += [(getattr(noise, op)(item["text"], rng), item["label"]) for op in TYPOS]
    return out


def test_typos_in_the_tuning_commands() -> None:
    # 786 of 7,980 misread before the second round, 274 after (the bank's classes held fixed,
    # which keeps some: "solow down" stays FOLLOW because a bank noise variant is)
    variants = _typo_variants()
    assert len(variants) == 7980
    assert sum(classify_intent(t).value != label for t, label in variants) == 274


def _exhaustive(word: str) -> str | None:
    """The spelling correction without its letter-set bound."""
    best, best_key = None, (99, True, True)
    for kw in lex.FUZZY_TARGETS:
        limit = min(_budget(len(kw)), _budget(len(word) + 1))
        d = _osa(word, kw, limit) if abs(len(kw) - len(word)) <= limit else limit + 1
        key = (d, not _neighbour_slip(word, kw), kw[0] != word[0])
        if d <= limit and key < best_key:
            best, best_key = kw, key
    return best


def test_the_letter_bound_changes_no_correction() -> None:
    words = {w for text, _ in _typo_variants() for raw in _raw_words(text) for w in [raw.replace("'", "")]
             if w.isalpha() and len(w) >= 3 and w not in lex.KNOWN}
    assert len(words) > 1000
    assert [w for w in sorted(words) if _fuzzy(w) != _exhaustive(w)] == []


@pytest.mark.parametrize(("text", "expected"), [
    # the first held-out set's misses
    ("The turn is about a mile away, on the right.", Intent.RIGHT),
    ("Stay on the motorway past this exit.", Intent.FOLLOW),
    ("Don't turn yet, it's the next left.", Intent.LEFT),
    ("Ease off, you're going too fast.", Intent.STOP),
    ("Take it slow through here.", Intent.STOP),
    ("Floor it!", Intent.FOLLOW),
    ("Hurry up, we'll miss the train.", Intent.FOLLOW),
    ("Drop me at the corner.", Intent.STOP),
    # without punctuation: where a negation ends, where the ego's part starts
    ("The turn is about a mile away on the right", Intent.RIGHT),
    ("Don't turn yet it's the next left", Intent.LEFT),
    ("Don't overtake here stay in your lane", Intent.FOLLOW),
    ("Not right left at the lights", Intent.LEFT),
    ("No not left right", Intent.RIGHT),
    ("Never mind the turn go straight on", Intent.STRAIGHT),
    ("Instead of the motorway take the left turn", Intent.LEFT),
    ("Turn left; ignore the sign saying go straight.", Intent.LEFT),  # reported, not given
    ("The truck ahead is turning right wait behind it", Intent.STOP),
    ("The car in front wants to turn left you turn right", Intent.RIGHT),
    ("Those cyclists are turning right let them pass", Intent.STOP),
    ("The car ahead is turning left", Intent.UNKNOWN),
    # fillers, asides and "Right," as a discourse marker
    ("Please the car ahead is turning left.", Intent.UNKNOWN),
    ("Now the bus in front is turning right.", Intent.UNKNOWN),
    ("Not the first right, the second one please.", Intent.RIGHT),
    ("If it's not too much trouble turn left at the lights", Intent.LEFT),
    ("Right, carry on down the high street.", Intent.FOLLOW),
    ("Right, at the lights.", Intent.RIGHT),
    ("Right, then left.", Intent.LEFT),
    # typos of words that became correction targets
    ("Pull ovre here.", Intent.STOP),
    ("Don't turn right unitl the cars have passed.", Intent.RIGHT),
    # the third round, from the second held-out set's misses
    ("Fork right after the bridge.", Intent.RIGHT),
    ("Use the slip road to leave the dual carriageway.", Intent.RIGHT),
    ("Come off the roundabout at the first opportunity.", Intent.RIGHT),
    ("Take the second turning off the roundabout.", Intent.STRAIGHT),
    ("Hold it here for a sec.", Intent.STOP),
    ("Pull in at the next lay-by.", Intent.STOP),
    ("Step on it!", Intent.FOLLOW),
    ("Take it easy, there's ice.", Intent.STOP),
    ("Bring your speed down to thirty.", Intent.STOP),
    ("There's a speed bump coming up.", Intent.STOP),
    ("Pick up some speed.", Intent.FOLLOW),
    ("Follow the road round to the left.", Intent.FOLLOW),
    ("That bus is pulling out, let it go first.", Intent.STOP),
    ("Let the bus pass before you turn left.", Intent.LEFT),
    ("Pass the tractor on the right when it's clear.", Intent.LANE_RIGHT),
    ("First right once we're over the bridge.", Intent.RIGHT),
    ("If the left lane is free, move into it.", Intent.LANE_LEFT),
    ("Don't take the first left, take the second.", Intent.LEFT),
    ("Left, and straight after that a right.", Intent.RIGHT),
    ("Proceed straight after the stop sign.", Intent.STRAIGHT),  # "after" alone is no "at once"
    ("Second street on the right is ours.", Intent.RIGHT),
    # after the third held-out set was read: its misses
    ("Switch to the right lane, the left one is ending.", Intent.LANE_RIGHT),
    ("Get off at the next junction.", Intent.RIGHT),
    ("Let me off at the corner.", Intent.STOP),
    ("Hurry, we're late.", Intent.FOLLOW),
    ("Hold this lane.", Intent.FOLLOW),
    ("That car wants to pull out, let it in.", Intent.STOP),
    ("Speed camera ahead.", Intent.STOP),
    ("Road narrows ahead.", Intent.STOP),
    ("Don't merge yet.", Intent.FOLLOW),
    ("Don't wait, go now.", Intent.FOLLOW),
    ("Left at the lights, then right after the church.", Intent.RIGHT),
    ("Right after the church, turn left.", Intent.LEFT),  # "right" there only intensifies
    ("slwo down", Intent.STOP),
    ("Turn left at the junction in 150 meters.", Intent.LEFT),  # "let ... in" needs its object
])
def test_second_round_rules(text: str, expected: Intent) -> None:
    assert classify_intent(text) is expected
