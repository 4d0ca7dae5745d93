"""The four counterfactual families: guarantees of every variant of every bundled route."""

from __future__ import annotations

import json

import numpy as np
import pytest

from icrsumo.core.errors import InputError
from icrsumo.core.types import Intent
from icrsumo.instructions.banks import CONTRADICTS, load_banks
from icrsumo.instructions.families import FAMILIES, make_variants
from icrsumo.instructions.intent import classify_intent
from icrsumo.instructions.store import read_instruction_sets


def _files(generated):
    for d in generated.values():
        for f in sorted(d.glob("*.json")):
            if f.name != "index.json":
                yield f


def test_every_route_has_32_valid_variant_sequences(generated):
    n_routes = 0
    for f in _files(generated):
        sets = read_instruction_sets(f)
        base, variants = sets[0], sets[1:]
        assert len(variants) == 32
        assert [(v.family, v.k) for v in variants] == [(fam, k) for fam in FAMILIES for k in range(8)]
        for v in variants:
            assert [(i.id, i.trigger) for i in v.instructions] == \
                [(i.id, i.trigger) for i in base.instructions]
            assert v.seed == 2026
            for b, i in zip(base.instructions, v.instructions):
                assert i.source == b.text and i.template and i.intent == b.intent
                got = classify_intent(i.text)
                if v.family in ("paraphrase", "noise"):
                    assert got == b.intent, (i.text, b.text)
                    assert ("[x]" in i.text) == ("[x]" in b.text)
                elif v.family == "ambiguity":
                    assert got == Intent.UNKNOWN and "[x]" not in i.text
                else:
                    assert got in CONTRADICTS[b.intent], (i.text, b.text)
                    assert ("[x]" in i.text) == ("[x]" in b.text)
        n_routes += 1
    assert n_routes == 64


def test_k_draws_vary_within_a_family(generated):
    f = next(_files(generated))
    sets = read_instruction_sets(f)
    for fam in FAMILIES:
        fam_sets = [s for s in sets if s.family == fam]
        for n in range(len(sets[0].instructions)):
            templates = [s.instructions[n].template for s in fam_sets]
            assert len(set(templates)) == 8, (fam, templates)


def test_documents_record_provenance(generated):
    f = next(_files(generated))
    doc = json.loads(f.read_text())
    assert doc["seed"] == 2026 and doc["k"] == 8 and doc["generator"] == "templates"
    assert doc["families"] == list(FAMILIES) and len(doc["banks_sha256"]) == 64
    ins = doc["sets"][1]["instructions"][0]
    assert set(ins) >= {"id", "trigger", "text", "intent", "type", "distance", "template", "source",
                        "classified"}


def test_seed_changes_draws_and_k_bounds(generated):
    banks = load_banks()
    base = read_instruction_sets(next(_files(generated)))[0]
    a = make_variants(base, FAMILIES, 8, banks, 2026, np.random.default_rng(1))
    b = make_variants(base, FAMILIES, 8, banks, 2026, np.random.default_rng(1))
    c = make_variants(base, FAMILIES, 8, banks, 2026, np.random.default_rng(2))
    assert a == b and a != c
    with pytest.raises(InputError, match="cannot draw K=40"):
        make_variants(base, ("paraphrase",), 40, banks, 2026, np.random.default_rng(1))
