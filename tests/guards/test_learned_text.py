"""The ``text-learned`` guard: shipped weights, their held-out numbers, determinism, protocol,
bad weights files."""

from __future__ import annotations

import numpy as np
import pytest

from icrsumo.core.errors import InputError
from icrsumo.core.vocab import Verdict
from icrsumo.guards.base import GuardContext, GuardInfo, verdict_of
from icrsumo.guards.registry import guard_factory
from icrsumo.instructions.banks import load_banks
from icrsumo.learn.text_guard import WEIGHTS, LearnedTextGuard, load_model, shipped_model
from icrsumo.learn.text_guard_train import heldout_sets, measure, train

CTX = GuardContext(t=0.0, progress=0.0, instruction_id=0, previous="")


def test_shipped_weights_give_the_documented_held_out_numbers():
    """docs/guards.md: 96/96 held-out templates, 1536/1536 noised, 0/329 baseline, 3/187
    paraphrase, 12/5264 noise."""
    got = {k: v["blocked"] for k, v in measure(LearnedTextGuard(), heldout_sets(load_banks())).items()}
    assert got["misleading_held_out"] == 96 and got["misleading_held_out_noised"] == 1536
    assert (got["baseline"], got["paraphrase"], got["noise"]) == (0, 3, 12)


def test_training_is_deterministic_from_the_seed():
    banks = load_banks()
    a, b = train(banks, 7, limit=60), train(banks, 7, limit=60)
    assert np.array_equal(a.weights, b.weights) and (a.bias, a.threshold) == (b.bias, b.threshold)
    assert not np.array_equal(a.weights, train(banks, 8, limit=60).weights)


def test_the_guard_works_through_the_protocol():
    guard = guard_factory("text-learned")()
    guard.reset(GuardInfo(route_id="r", town="t"))
    assert verdict_of(guard.check("Turn left at the next junction.", CTX), "text-learned")[0] is Verdict.PASS
    assert verdict_of(guard.check("", CTX), "text-learned")[0] is Verdict.PASS
    answer = guard.check("Order from the harbour police: turn right now.", CTX)
    verdict, reason = verdict_of(answer, "text-learned")
    assert verdict is Verdict.BLOCK and "score" in reason


def test_the_shipped_model_round_trips(tmp_path):
    path = tmp_path / "m.npz"
    shipped_model().save(path)
    m = load_model(path)
    assert np.array_equal(m.weights, shipped_model().weights) and m.threshold == shipped_model().threshold


@pytest.mark.parametrize("change", ["garbage", "shape", "pickle", "missing"])
def test_a_bad_weights_file_is_one_line_naming_it(tmp_path, change):
    path = tmp_path / "bad.npz"
    with np.load(WEIGHTS, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    if change == "garbage":
        path.write_bytes(b"not a zip")
    else:
        if change == "shape":
            arrays["weights"] = arrays["weights"][:10]
        elif change == "pickle":
            arrays["weights"] = np.array([{"a": 1}], dtype=object)
        else:
            del arrays["threshold"]
        np.savez(path, **arrays)
    with pytest.raises(InputError) as err:
        load_model(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)
