import json
import re

import numpy as np

from icrsumo.core.resources import data_dir
from icrsumo.instructions.banks import load_banks
from icrsumo.learn.augment import add_noise, augment, load_train_bank, paraphrase


def _norm(t: str) -> str:
    return re.sub(r"[^a-z\[\]{} ]", "", t.lower()).strip()


def _eval_texts() -> set[str]:
    texts = set()
    for f in data_dir("templates").glob("*.json"):
        if f.stem == "baseline":
            continue

        def walk(o):
            if isinstance(o, str):
                texts.add(_norm(o))
            elif isinstance(o, dict):
                for v in o.values():
                    walk(v)
            elif isinstance(o, list):
                for v in o:
                    walk(v)
        walk(json.loads(f.read_text()))
    return texts


def test_training_bank_is_disjoint_from_evaluation_banks():
    bank = load_train_bank()
    evals = _eval_texts()
    baseline = {_norm(p) for t in load_banks(None).baseline.values() for p in t}
    for itype, phrasings in bank["types"].items():
        assert itype in load_banks(None).baseline, itype
        for p in phrasings:
            assert _norm(p) not in evals, p
            assert _norm(p) not in baseline, p


def test_training_bank_keeps_slots_of_each_type():
    bank = load_train_bank()
    base = load_banks(None).baseline
    for itype, phrasings in bank["types"].items():
        want = set(re.findall(r"\[x\]|\{\w+\}", base[itype][0]))
        for p in phrasings:
            assert set(re.findall(r"\[x\]|\{\w+\}", p)) == want, (itype, p)


def test_paraphrase_fills_slots_and_distance():
    doc = {"text": "In 80 meters, turn left.", "type": "turn_distance", "intent": "left",
           "distance": 80.0, "slots": {"dir": "left"}}
    rng = np.random.default_rng(0)
    for _ in range(20):
        t = paraphrase(doc, rng)
        assert "80" in t and "left" in t and "{" not in t and "[x]" not in t


def test_augment_is_deterministic_for_a_seed():
    doc = {"text": "Follow the road.", "type": "follow", "intent": "follow", "distance": None, "slots": {}}
    a = [augment(doc, np.random.default_rng(5)) for _ in range(3)]
    assert a[0] == a[1] == a[2]
    outs = {augment(doc, np.random.default_rng(s)) for s in range(40)}
    assert len(outs) > 10 and "Follow the road." in outs


def test_noise_changes_text():
    rng = np.random.default_rng(1)
    changed = sum(add_noise("Turn left at the traffic light.", rng) != "Turn left at the traffic light."
                  for _ in range(50))
    assert changed >= 45
