"""bev-minilm's pretrained sentence encoder: what ships, what it computes (exactly: the float64
fast path equals the int64 reference bit for bit), and the one-line errors for a missing or
damaged file or a missing tokenizer library, before any episode runs."""

from __future__ import annotations

import numpy as np
import pytest

from icrsumo.app.cli.main import main
from icrsumo.core.errors import InputError
from icrsumo.learn import minilm
from icrsumo.learn.minilm import DIM, MODEL, TOKENIZER, SentenceEncoder, int64_mm


def test_the_encoder_ships_with_its_notice_and_licence():
    assert MODEL.is_file() and TOKENIZER.is_file() and MODEL.stat().st_size < 30 * 2**20
    notice = (MODEL.parent / "NOTICE").read_text()
    assert "all-MiniLM-L6-v2" in notice and "Apache License" in notice
    assert "Apache License" in (MODEL.parent / "LICENSE-Apache-2.0").read_text()


def test_embeddings_are_normalised_deterministic_and_mean_something():
    enc = SentenceEncoder()
    a = enc.embed("Turn left at the next intersection.")
    assert a.shape == (DIM,) and a.dtype == np.float32 and abs(float(a @ a) - 1) < 1e-4
    assert np.array_equal(a, SentenceEncoder().embed("Turn left at the next intersection."))
    assert np.array_equal(enc.embed_many(["x", "Turn left at the next intersection."])[1], a)
    para = enc.embed("Take a left at the upcoming junction.")
    other = enc.embed("The weather is lovely today.")
    assert float(a @ para) > float(a @ other) + 0.2
    assert enc.embed("word " * 400).shape == (DIM,)   # cut to the model's 128 tokens


def test_missing_and_damaged_files_are_one_line_errors(tmp_path):
    with pytest.raises(InputError, match="the sentence encoder's file is missing.*tools/export_minilm.py"):
        SentenceEncoder(model=tmp_path / "none.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not an archive")
    with pytest.raises(InputError, match="bad.npz: not a readable encoder file"):
        SentenceEncoder(model=bad)
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(InputError, match="other.npz: __format__: not an icrsumo sentence encoder file"):
        SentenceEncoder(model=tmp_path / "other.npz")
    with np.load(MODEL, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files if k != "layers.3.q.q"}
    np.savez(tmp_path / "partial.npz", **arrays)
    with pytest.raises(InputError, match="partial.npz: layers.3.q.q: missing"):
        SentenceEncoder(model=tmp_path / "partial.npz")
    tok = tmp_path / "tokenizer.json"
    tok.write_text("{")
    with pytest.raises(InputError, match="tokenizer.json: not a readable tokenizer"):
        SentenceEncoder(tokenizer=tok)


@pytest.mark.sumo
def test_without_the_tokenizer_library_evaluate_stops_before_any_episode(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(minilm, "tokenizers_missing", lambda: True)
    minilm.encoder.cache_clear()
    out = tmp_path / "out"
    try:
        assert main(["evaluate", "--agent", "bev-minilm", "--routes", "tiny_003", "--k", "1", "--quiet",
                     "--out", str(out)]) == 2
    finally:
        minilm.encoder.cache_clear()
    line = capsys.readouterr().err.strip()
    assert "pip install 'icrsumo[minilm]'" in line and "\n" not in line
    assert not out.exists()


def test_token_states_and_the_last_layer_rebuild_the_embedding():
    """``states`` enter the last layer; that layer, dequantised into torch, maps them to (nearly)
    the graph's own embedding: where bev-minilm-tuned's fine-tuning starts."""
    import torch

    from icrsumo.learn.nets import MINILM_SHAPE, BertLayer, sentence_embedding

    enc = SentenceEncoder()
    text = "After the bike has passed, turn left at the lights."
    states = enc.states(text)
    n = len(enc.tokenizer.encode(text).ids)
    assert states.shape == (n, DIM) and states.dtype == np.float32
    assert np.array_equal(states, SentenceEncoder().states(text))
    layer = BertLayer(*MINILM_SHAPE)
    layer.load_state_dict({k: torch.from_numpy(v) for k, v in enc.last_layer().items()})
    with torch.no_grad():
        x = torch.from_numpy(states)[None]
        out = sentence_embedding(layer(x, torch.zeros(1, 1, 1, n)), torch.ones(1, n))[0].numpy()
    assert float(out @ enc.embed(text)) > 0.99


def test_the_fast_path_equals_the_int64_reference_bit_for_bit():
    """Every product is a sum of integers below 2**53: float64 BLAS (any blocking, threads, FMA)
    gives the int64 result exactly, so the embedding is the same on every CPU."""
    import json

    from icrsumo.learn.augment import TRAIN_BANK

    bank = json.loads(TRAIN_BANK.read_text())
    texts = sorted({t.replace("[x]", "120") for ts in bank["types"].values() for t in ts})[::6]
    texts += ["", "tuRn lft at teh nxt intrsection pls", "word " * 400]
    fast, ref = SentenceEncoder(), SentenceEncoder(mm=int64_mm)
    assert len(texts) >= 20
    for t in texts:
        assert np.array_equal(fast.embed(t), ref.embed(t)), t
    assert np.array_equal(fast.states(texts[0]), ref.states(texts[0]))
