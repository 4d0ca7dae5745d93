"""Exact checkpoints (icrsumo.learn.exact): the float32 fast path equals the int64 reference bit
for bit on recorded observations (batch 1 and 32, 1 and 2 BLAS threads), the exporter keeps the
float network's outputs, files are checked on load, bad input is one line, and inference needs
no torch. Recorded observations come from a real collection (SUMO) on two tiny-suite routes."""

import json
import subprocess
import sys
import zipfile

import numpy as np
import pytest
import torch
from threadpoolctl import threadpool_limits

from icrsumo.core.errors import InputError
from icrsumo.learn import nets
from icrsumo.learn.collect import CollectOptions, collect
from icrsumo.learn.config import config_dict
from icrsumo.learn.exact import checkpoint as xck
from icrsumo.learn.exact import graph
from icrsumo.learn.exact import model as exact_model
from icrsumo.learn.exact.graph import EXACT_LIMIT
from icrsumo.learn.exact.model import ExactPolicy
from icrsumo.learn.exact.quantize import augmented_texts, calibration_frames, export_file
from icrsumo.learn.exact.reference import int64_engine


@pytest.fixture(scope="module")
def recorded(converted, tmp_path_factory):
    """A collect folder (2 routes, clean and perturbed passes) and its frames."""
    out = tmp_path_factory.mktemp("collect")
    collect(CollectOptions(suite=str(converted["tiny"]), passes=2, every=2, limit=2), out, quiet=True)
    return out, calibration_frames([out], limit=100_000)


def _float_checkpoint(path, encoder, **kw):
    vocab = ("<pad>", "<unk>", "turn", "left", "right", "go", "straight", "at", "the", "next", "intersection",
             "in", "<num>", "meters", "follow", "road", "lane", "change", "to") if encoder == "token" else ()
    cfg = nets.ModelConfig(encoder=encoder, text_len=384 if encoder == "minilm" else 48, buckets=512,
                           vocab=vocab, width=8, hidden=32, lang=16, embed=8, **kw)
    model = nets.build_model(cfg, seed=3)
    weights = {k: v.detach().float() for k, v in model.state_dict().items()}
    nets.save({"format": nets.CHECKPOINT_FORMAT, "config": config_dict(cfg), "model": weights,
               "meta": {}}, path)
    return path


@pytest.fixture(scope="module", params=["ngram", "token", "minilm"])
def exported(request, recorded, tmp_path_factory):
    if request.param == "minilm":
        pytest.importorskip("tokenizers")
    folder, frames = recorded
    d = tmp_path_factory.mktemp(f"exact-{request.param}")
    src = _float_checkpoint(d / "model.pt", request.param)
    out = d / "model.npz"
    export_file(src, out, [folder], frames=2000)
    return src, out, frames


def _call(policy, frames, idx):
    bev, texts, speed, stopped = frames
    return policy(bev[idx], [texts[i] for i in idx], speed[idx], stopped[idx])


def _same(a, b):
    return all(a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k]) for k in a)


def test_fast_path_equals_the_int64_reference_bit_for_bit(exported):
    _, path, frames = exported
    n = len(frames[0])
    assert n > 300
    ref = ExactPolicy(path, engine=int64_engine)
    fast = ExactPolicy(path)
    want = _call(ref, frames, np.arange(n))
    for threads in (1, 2):
        with threadpool_limits(threads, user_api="blas"):
            for lo in range(0, n, 32):          # batches of 32 (the last shorter)
                idx = np.arange(lo, min(lo + 32, n))
                got = _call(fast, frames, idx)
                assert _same(got, {k: v[idx] for k, v in want.items()})
            for i in range(0, n, 7):            # batch 1
                got = _call(fast, frames, np.array([i]))
                assert _same(got, {k: v[i:i + 1] for k, v in want.items()})


def _dense_image(a, mm, bev):
    """The image stage as the dense graph computes it: every patch and window multiplied."""
    b, _, h, w = bev.shape
    x = graph.requant(mm(graph.patches4(bev), "stem"), a["stem.m"], 0, float(a["c2.top"]))
    x = graph.requant(mm(graph.im2col3s2(x, b, h // 4, w // 4), "c2"), a["c2.m"], 0, float(a["c3.top"]))
    acc = mm(graph.im2col3s2(x, b, h // 8, w // 8), "c3")
    return acc.reshape(b, h // 16, w // 16, -1)


def test_only_new_rows_are_multiplied_and_the_bits_stay_the_dense_graphs(exported):
    _, path, frames = exported
    bev = frames[0]
    for engine in (None, int64_engine):
        policy = ExactPolicy(path, engine=engine)
        a, mm = policy.arrays, policy.mm
        drawn = graph.patches4(bev).any(axis=1)
        assert 0.2 < 1 - drawn.mean() < 0.95        # the recorded frames have empty patches
        full = np.full((2, *bev.shape[1:]), 255, np.uint8)
        blank = np.zeros((2, *bev.shape[1:]), np.uint8)
        for x in (bev[:64], full, blank, np.concatenate([blank[:1], bev[:1], full[:1]])):
            assert graph.image(a, mm, x).acc.tobytes() == _dense_image(a, mm, x).tobytes()
        before = None
        for i in range(0, len(bev), 3):             # each from the frame before (most of them close)
            x = bev[i:i + 1]
            if i % 2:                               # and a few pixels drawn or erased
                x = x.copy()
                x[0, i % 7, 40:43, 60 + i % 9:64 + i % 9] ^= 255
            got = graph.image(a, mm, x, before=before)
            assert got.acc.tobytes() == _dense_image(a, mm, x).tobytes()
            before = got
        # a change that only erases: the one patch that changed is empty now, so the stem
        # multiplies no row at all
        x = bev[:1].copy()
        i, j = np.argwhere(graph.drawn(x)[0])[0]
        before = graph.image(a, mm, x)
        x = x.copy()                                # the Image keeps the array it was given
        x[0, :, 4 * i:4 * i + 4, 4 * j:4 * j + 4] = 0
        got = graph.image(a, mm, x, before=before)
        assert got is not before
        assert got.acc.tobytes() == _dense_image(a, mm, x).tobytes()


def test_fuse_is_the_three_stages_in_one_call(exported):
    _, path, frames = exported
    bev, texts, speed, stopped = frames
    policy = ExactPolicy(path, reuse=False)
    got = graph.fuse(policy.arrays, policy.mm, bev[:16], policy.language(texts[:16]), speed[:16],
                     stopped[:16])
    assert _same(got, _call(policy, frames, np.arange(16)))


def _counting(rows):
    """An engine factory whose products append (layer, rows multiplied) to ``rows``."""
    def make(arrays):
        inner = exact_model.FloatEngine(arrays)

        def mm(x, layer):
            rows.append((layer, len(x)))
            return inner(x, layer)
        return mm
    return make


def test_a_call_starts_from_the_call_before_with_the_same_bits(exported):
    _, path, frames = exported
    bev, texts, speed, stopped = frames
    rows = []
    fresh, reusing = ExactPolicy(path, reuse=False), ExactPolicy(path, engine=_counting(rows))
    mine = bev[0].copy()
    touched = mine.copy()
    touched[2, 60:62, 60:62] = 255                 # one vehicle pixel more, near the middle
    # a frame; the same BEV again; with other text and speed; the BEV touched; a new frame, twice
    plan = [(mine, 0, 0), (mine, 0, 1), (mine, 3, 2), (touched, 3, 2), (bev[5], 5, 5), (bev[5], 5, 5)]
    image_rows = []
    for x, t, s in plan:
        args = ([texts[t]], speed[s:s + 1], stopped[s:s + 1])
        rows.clear()
        got = reusing(x[None], *args)
        image_rows.append(sum(n for layer, n in rows if layer in ("stem", "c2", "c3")))
        assert _same(got, fresh(x[None], *args))
    dense = 32 * 32 + 16 * 16 + 8 * 8
    assert 0 < image_rows[0] < dense and image_rows[1] == image_rows[2] == image_rows[5] == 0
    assert 0 < image_rows[3] <= 1 + 4 + 4         # one patch, the windows that hold it
    reusing(mine[None], *args)
    mine[:, :16] = 255                             # the caller's array changed after its call
    assert _same(reusing(mine[None], *args), fresh(mine[None], *args))
    idx = np.array([0, 0, 1])
    assert _same(_call(reusing, frames, idx), _call(fresh, frames, idx))


def test_exact_outputs_follow_the_float_network(exported):
    src, path, frames = exported
    idx = np.arange(0, len(frames[0]), 3)
    got = _call(ExactPolicy(path), frames, idx)
    want = _call(nets.Policy(src, runtime="torch"), frames, idx)
    scale = np.abs(want["waypoints"]).max()
    err = np.abs(got["waypoints"] - want["waypoints"]) / scale
    assert np.median(err) < 0.02 and err.max() < 0.15
    assert np.corrcoef(got["speed"], want["speed"])[0, 1] > 0.98


def test_saved_file_loads_to_the_same_policy_and_records_its_checks(exported, tmp_path):
    _, path, frames = exported
    ck = xck.load(path)
    assert ck.meta["source"] == "model.pt" and ck.meta["calibration_frames"] > 300
    assert max(ck.meta["bounds"].values()) < EXACT_LIMIT
    xck.save(ck, tmp_path / "again.npz")
    idx = np.arange(0, 40)
    again = ExactPolicy(tmp_path / "again.npz")
    assert _same(_call(ExactPolicy(path), frames, idx), _call(again, frames, idx))


def test_calibration_texts_come_from_the_training_bank(recorded):
    folder, _ = recorded
    texts = augmented_texts([folder])
    assert texts == augmented_texts([folder]) and len(set(texts)) > 10


def _rewrite(path, out, change):
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    change(arrays)
    np.savez(out, **arrays)
    return out


@pytest.mark.parametrize("change, place, words", [
    (lambda a: a.pop("fc.w"), "arrays", "1 missing (e.g. fc.w)"),
    (lambda a: a.update({"fc.w": a["fc.w"].astype(np.int16)}), "fc.w", "is int16"),
    (lambda a: a.update({"head.d": a["head.d"] * np.float32("nan")}), "head.d", "non-finite"),
    (lambda a: a.update({"c4.top": np.array(300, np.int32)}), "c4.top", "not in 1..255"),
    (lambda a: a.update({"fc.b": a["fc.b"] + np.int32(EXACT_LIMIT)}), "fc.w", "2**24"),
    (lambda a: a.update({"__doc__": np.frombuffer(b'{"format": "other/1"}', np.uint8)}), "__doc__.format",
     "not an icrsumo exact checkpoint"),
])
def test_a_damaged_checkpoint_is_one_line_naming_the_array(exported, tmp_path, change, place, words):
    _, path, _ = exported
    bad = _rewrite(path, tmp_path / "bad.npz", change)
    with pytest.raises(InputError) as err:
        xck.load(bad)
    assert err.value.place == place and words in err.value.problem


def test_a_pickled_array_is_refused_without_running_it(exported, tmp_path):
    _, path, _ = exported
    bad = _rewrite(path, tmp_path / "pickled.npz", lambda a: a.update({"fc.w": np.array([{"x": 1}], object)}))
    with pytest.raises(InputError, match="not a readable exact checkpoint"):
        xck.load(bad)
    (tmp_path / "junk.npz").write_bytes(b"PK\x03\x04 not a zip")
    with pytest.raises(InputError, match="not a readable exact checkpoint"):
        xck.load(tmp_path / "junk.npz")
    assert zipfile.is_zipfile(path)


def test_export_refuses_what_cannot_be_exact_and_writes_nothing(recorded, tmp_path):
    folder, _ = recorded
    src = _float_checkpoint(tmp_path / "model.pt", "ngram")
    ck = torch.load(src, weights_only=True)
    # a bias far above what the weights can reach: in accumulator units no activation top fits
    ck["model"]["fc.weight"] = torch.full_like(ck["model"]["fc.weight"], 1e-6)
    ck["model"]["fc.bias"] = torch.ones_like(ck["model"]["fc.bias"])
    torch.save(ck, tmp_path / "wide.pt")
    with pytest.raises(InputError) as err:
        export_file(tmp_path / "wide.pt", tmp_path / "wide.npz", [folder], frames=200)
    assert err.value.place == "fc" and "2**24" in err.value.problem
    assert not (tmp_path / "wide.npz").exists()


def test_export_exact_command(recorded, tmp_path):
    folder, _ = recorded
    src = _float_checkpoint(tmp_path / "model.pt", "ngram")
    cmd = [sys.executable, "-m", "icrsumo", "export-exact", str(src), "--calibration", str(folder),
           "--frames", "300"]
    ok = subprocess.run([*cmd, "--out", str(tmp_path / "m.npz")], capture_output=True, text=True, timeout=300)
    assert ok.returncode == 0, ok.stderr
    assert "< 2**24" in ok.stdout and (tmp_path / "m.npz").is_file()
    bad = subprocess.run([*cmd, "--out", str(tmp_path / "m.pt")], capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and ".npz" in bad.stderr
    assert "Traceback" not in bad.stderr and not (tmp_path / "m.pt").exists()
    pytest.importorskip("tokenizers")
    cfg = nets.ModelConfig(encoder="minilm-tuned", text_len=2 * 384, width=8, hidden=32, lang=16, embed=8)
    model = nets.build_model(cfg, seed=3)
    tuned = tmp_path / "tuned.pt"
    nets.save({"format": nets.CHECKPOINT_FORMAT, "config": config_dict(cfg),
               "model": {k: v.detach().float() for k, v in model.state_dict().items()}, "meta": {}}, tuned)
    r = subprocess.run([*cmd[:4], str(tuned), *cmd[5:], "--out", str(tmp_path / "t.npz")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "Traceback" not in r.stderr and not (tmp_path / "t.npz").exists()
    assert "config.encoder" in r.stderr and "no exact form" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_inference_needs_no_torch(exported):
    _, path, frames = exported
    bev, texts, speed, stopped = frames
    np.save(path.with_suffix(".bev.npy"), bev[:3])
    code = f"""
import sys, json, numpy as np
sys.modules["torch"] = None          # any import of torch fails
from icrsumo.learn.agent import LearnedAgent
from icrsumo.learn.exact.model import ExactPolicy
p = ExactPolicy({str(path)!r})
bev = np.load({str(path.with_suffix('.bev.npy'))!r})
out = p(bev, {json.dumps(texts[:3])}, np.array({speed[:3].tolist()}), np.array({stopped[:3].tolist()}))
print(json.dumps(out["waypoints"].tolist()))
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    want = ExactPolicy(path)(bev[:3], texts[:3], speed[:3], stopped[:3])["waypoints"]
    assert np.array_equal(np.array(json.loads(r.stdout), np.float32), want)


def test_every_shipped_agent_is_exact_on_recorded_observations(converted):
    """The shipped checkpoints' fast path equals the int64 reference on frames recorded on the
    tiny suite (tools/exact_proof.py runs the same on 10,000 frames per checkpoint)."""
    from icrsumo.learn.agent import CHECKPOINTS
    from icrsumo.learn.exact.proof import prove, record
    from icrsumo.world.scenario import find_scenarios

    frames = record(find_scenarios(converted["tiny"])[:3], 256, every=3)
    assert len(frames) == 256 and len(set(frames.texts)) >= 2
    shipped = sorted(CHECKPOINTS.glob("*.npz"))
    assert sorted(p.stem for p in shipped) == ["bev-minilm", "bev-minilm-aug", "bev-ngram", "bev-ngram-aug",
                                         "bev-token"]
    for path in shipped:
        r = prove(path, frames, variants=((1, 1), (2, 32)))
        assert r.exact, (path.name, r.first)


def test_shipped_agents_drive_without_torch():
    code = """
import sys, numpy as np
sys.modules["torch"] = None; sys.modules["onnxruntime"] = None
from icrsumo.agents.base import EpisodeInfo, Observation
from icrsumo.agents.registry import agent_factory
for name in ("bev-ngram-aug", "bev-token", "bev-minilm-aug"):
    a = agent_factory(name)()
    obs = Observation(t=0.0, bev=np.zeros((7, 128, 128), np.uint8), speed=3.0,
                      instruction="Turn left at the next intersection.", instruction_id=0, notice="")
    act = a.act(obs)
    assert act.waypoints.shape == (8, 2), act
print("ok")
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=180)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr[-2000:]
