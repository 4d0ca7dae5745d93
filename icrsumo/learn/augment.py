"""Instruction augmentation for training (``icrsumo train --augment-instructions``).

Paraphrases come from the training bank ``icrsumo/learn/data/train_bank.json`` (same
instruction types and slots as the baseline bank; none of its texts is in an evaluation bank)
and noise from the training primitives below (random-letter substitution, letter drop, letter
repeat, adjacent swap, whitespace jitter, case flips, filler words). The evaluation banks
(paraphrase, ambiguity, noise, misleading) are never read here. Pure functions of their
arguments and a ``numpy.random.Generator``.
"""

from __future__ import annotations

import json
import re
from functools import cache
from pathlib import Path

import numpy as np

from icrsumo.core.types import Instruction, Intent
from icrsumo.instructions.banks import ORDINALS, fill

TRAIN_BANK = Path(__file__).resolve().parent / "data" / "train_bank.json"
_LETTERS = "abcdefghijklmnopqrstuvwxyz"
_WORD = re.compile(r"[A-Za-z]{3,}")


def instruction_slots(ins: Instruction) -> dict[str, str]:
    """The slot values of a baseline instruction ({dir}, {side}, {exit}), read back from its
    intent and text."""
    slots: dict[str, str] = {}
    if ins.intent in (Intent.LEFT, Intent.RIGHT):
        slots["dir"] = ins.intent.value
    if ins.intent in (Intent.LANE_LEFT, Intent.LANE_RIGHT):
        slots["side"] = "left" if ins.intent == Intent.LANE_LEFT else "right"
    if ins.type == "roundabout_exit":
        words = re.findall(r"[a-z]+", ins.text.lower())
        slots["exit"] = next((o for o in ORDINALS if o in words), "first")
    return slots


@cache
def load_train_bank(path: str = str(TRAIN_BANK)) -> dict:
    """The training bank: ``{"types": {type: [phrasing, ...]}, "noise": {"fillers": [...]}}``."""
    return json.loads(Path(path).read_text(encoding="utf-8"))


def paraphrase(doc: dict, rng: np.random.Generator, bank: dict | None = None) -> str:
    """A training-bank phrasing of instruction ``doc`` (keys type, slots, distance; as stored by
    ``icrsumo collect``); the shown text when the bank has no phrasing of its type."""
    bank = bank or load_train_bank()
    options = bank["types"].get(doc["type"])
    if not options:
        return doc["text"]
    text = fill(options[int(rng.integers(len(options)))], **doc.get("slots", {}))
    if doc.get("distance") is not None:
        text = text.replace("[x]", f"{doc['distance']:.0f}")
    return text


def _edit_word(text: str, rng: np.random.Generator, op: str) -> str:
    words = list(_WORD.finditer(text))
    if not words:
        return text
    m = words[int(rng.integers(len(words)))]
    w = m.group(0)
    i = int(rng.integers(len(w)))
    if op == "sub":
        w = w[:i] + _LETTERS[int(rng.integers(26))] + w[i + 1:]
    elif op == "drop":
        w = w[:i] + w[i + 1:]
    elif op == "repeat":
        w = w[:i] + w[i] + w[i:]
    elif op == "swap" and i + 1 < len(w):
        w = w[:i] + w[i + 1] + w[i] + w[i + 2:]
    return text[: m.start()] + w + text[m.end():]


def add_noise(text: str, rng: np.random.Generator, bank: dict | None = None) -> str:
    """``text`` with 1-3 training noise primitives applied."""
    bank = bank or load_train_bank()
    ops = ("sub", "drop", "repeat", "swap", "space", "lower", "upper", "flip", "filler")
    for _ in range(int(rng.integers(1, 4))):
        op = ops[int(rng.integers(len(ops)))]
        if op in ("sub", "drop", "repeat", "swap"):
            text = _edit_word(text, rng, op)
        elif op == "space":
            text = re.sub(r" ", lambda _: " " * int(rng.integers(0, 3)) or "", text, count=1)
        elif op == "lower":
            text = text.lower()
        elif op == "upper":
            text = text.upper()
        elif op == "flip":
            flips = rng.random(len(text)) < 0.15
            text = "".join(c.swapcase() if f else c for c, f in zip(text, flips))
        else:
            fillers = bank["noise"]["fillers"]
            text = f"{fillers[int(rng.integers(len(fillers)))]}, {text}"
    return text


def augment(doc: dict, rng: np.random.Generator, p_paraphrase: float = 0.5, p_noise: float = 0.3,
            bank: dict | None = None) -> str:
    """The text of ``doc`` as trained on: with probability ``p_paraphrase`` a training-bank
    paraphrase, then with probability ``p_noise`` training noise."""
    text = paraphrase(doc, rng, bank) if rng.random() < p_paraphrase else doc["text"]
    if rng.random() < p_noise:
        text = add_noise(text, rng, bank)
    return text
