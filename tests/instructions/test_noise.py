"""Noise primitives: placeholders survive, typos are single edits, draws are seeded."""

from __future__ import annotations

import numpy as np
import pytest

from icrsumo.instructions.noise import PRIMITIVES, apply_ops

TEXT = "Turn left at the intersection in [x] meters."


def _osa(a: str, b: str) -> int:
    """Optimal string alignment distance (for checking single edits)."""
    d = [[0] * (len(b) + 1) for _ in range(len(a) + 1)]
    for i in range(len(a) + 1):
        d[i][0] = i
    for j in range(len(b) + 1):
        d[0][j] = j
    for i in range(1, len(a) + 1):
        for j in range(1, len(b) + 1):
            cost = a[i - 1] != b[j - 1]
            d[i][j] = min(d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost)
            if i > 1 and j > 1 and a[i - 1] == b[j - 2] and a[i - 2] == b[j - 1]:
                d[i][j] = min(d[i][j], d[i - 2][j - 2] + 1)
    return d[-1][-1]


@pytest.mark.parametrize("op", sorted(PRIMITIVES))
def test_placeholder_survives_and_seeded(op):
    for seed in range(20):
        out = apply_ops(TEXT, [op], np.random.default_rng(seed))
        assert out.count("[x]") == 1
        assert out == apply_ops(TEXT, [op], np.random.default_rng(seed))


@pytest.mark.parametrize("op", ["neighbour", "transpose", "delete", "insert", "double"])
def test_typos_are_one_edit_in_one_word(op):
    changed = 0
    for seed in range(40):
        out = apply_ops(TEXT, [op], np.random.default_rng(seed))
        assert _osa(TEXT, out) <= 1
        diff = [(a, b) for a, b in zip(TEXT.split(), out.split(), strict=False) if a != b]
        assert len(diff) <= 1 and len(out.split()) == len(TEXT.split())
        changed += out != TEXT
    assert changed >= 30


def test_casing_and_punctuation():
    rng = np.random.default_rng(0)
    assert apply_ops(TEXT, ["upper"], rng) == "TURN LEFT AT THE INTERSECTION IN [x] METERS."
    assert apply_ops(TEXT, ["lower", "strip_punct"], rng) == "turn left at the intersection in [x] meters"
    assert apply_ops(TEXT, ["add_punct"], rng) != TEXT
