"""The control families: blank (no text) and shuffled (another maneuver's baseline text), and
the guarantee that selecting them leaves the paper's four families' draws unchanged."""

from __future__ import annotations

import pytest

from icrsumo.core.types import Intent
from icrsumo.core.vocab import CONTROL_FAMILIES, variants_of
from icrsumo.instructions.banks import baseline_catalogue, load_banks
from icrsumo.instructions.families import FAMILIES, make_variants
from icrsumo.instructions.generate import route_rng
from icrsumo.instructions.intent import classify_intent
from icrsumo.instructions.store import read_instruction_sets


@pytest.fixture(scope="module")
def banks():
    return load_banks(None)


def _baselines(generated):
    for d in generated.values():
        for f in sorted(d.glob("*.json")):
            if f.name != "index.json":
                yield read_instruction_sets(f)[0]


def test_the_catalogue_holds_every_maneuver_and_classifies_as_its_intent(banks):
    cat = baseline_catalogue(banks)
    intents = {intent for _, _, intent in cat}
    assert {Intent.LEFT, Intent.RIGHT, Intent.STRAIGHT, Intent.FOLLOW, Intent.LANE_LEFT,
            Intent.LANE_RIGHT} <= intents and Intent.STOP not in intents
    assert len({tid for tid, _, _ in cat}) == len(cat)
    for tid, text, intent in cat:
        assert "{" not in text, tid
        assert classify_intent(text.replace("[x]", "50")) == intent, (tid, text)


def test_blank_is_one_empty_sequence_and_shuffled_names_another_maneuver(generated, banks):
    for base in _baselines(generated):
        sets = make_variants(base, CONTROL_FAMILIES, 8, banks, 2026, route_rng(2026, base.route_id))
        blank = [s for s in sets if s.family == "blank"]
        shuffled = [s for s in sets if s.family == "shuffled"]
        assert len(blank) == variants_of("blank", 8) == 1 and len(shuffled) == 8
        assert all(i.text == "" and i.distance is None for i in blank[0].instructions)
        assert blank[0].notices == base.notices
        for s in shuffled:
            for b, i in zip(base.instructions, s.instructions):
                assert (i.id, i.trigger, i.intent, i.source) == (b.id, b.trigger, b.intent, b.text)
                if b.intent in (Intent.STOP, Intent.UNKNOWN):
                    assert i.text == b.text
                else:
                    assert classify_intent(i.text.replace("[x]", "50")) != b.intent, (b.text, i.text)
                    assert ("[x]" in i.text) == ("[x]" in b.text)
        texts = {tuple(i.text for i in s.instructions) for s in shuffled}
        assert len(texts) == 8  # drawn without replacement


def test_controls_leave_the_four_families_unchanged(generated, banks):
    base = next(_baselines(generated))
    def draw(families):
        return make_variants(base, families, 8, banks, 2026, route_rng(2026, base.route_id))

    four, six = draw(FAMILIES), draw(FAMILIES + CONTROL_FAMILIES)
    assert six[:len(four)] == four
    assert draw(FAMILIES + ("shuffled",))[len(four):] == six[len(four) + 1:]  # blank draws nothing
