"""The learned agents' CPU inference in ONNX Runtime (icrsumo.learn.runtime): the same network
as torch within float rounding, deterministic, independent of the batch, and the default."""

import numpy as np
import pytest

from icrsumo.core.errors import InputError
from icrsumo.learn.agent import CHECKPOINTS, LearnedAgent, act_batch
from icrsumo.learn.nets import Policy, onnx_bytes
from icrsumo.learn.runtime import INPUTS, OUTPUTS, OrtFuse

SHIPPED = sorted(p.stem for p in CHECKPOINTS.glob("*.pt"))
TEXTS = ["Turn left at the next intersection.", "Go straight.", "", "Change to the right lane",
         "Take the second exit at the roundabout, then follow the road for 120 m."]


def _inputs(n: int, seed: int) -> tuple[np.ndarray, list[str], np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    bev = (rng.random((n, 7, 128, 128)) < 0.08).astype(np.uint8) * 255
    bev[:, 0, :, 48:80] = 255  # a road ahead
    texts = [TEXTS[i % len(TEXTS)] for i in range(n)]
    speed = rng.uniform(0.0, 12.0, n).astype(np.float32)
    stopped = np.where(rng.random(n) < 0.3, rng.uniform(0.0, 6.0, n), 0.0).astype(np.float32)
    return bev, texts, speed, stopped


@pytest.mark.parametrize("name", SHIPPED)
def test_onnx_and_torch_agree_within_rounding(name):
    path = CHECKPOINTS / f"{name}.pt"
    onnx, torch_ = Policy(path, runtime="onnx"), Policy(path, runtime="torch")
    assert onnx.runtime == "onnx" and torch_.runtime == "torch"
    for seed in range(3):
        args = _inputs(8, seed)
        a, b = onnx(*args), torch_(*args)
        assert set(a) == set(b) == {"waypoints", "speed", "stop_prob"}
        for k in a:
            assert a[k].shape == b[k].shape and a[k].dtype == np.float32
        np.testing.assert_allclose(a["waypoints"], b["waypoints"], rtol=0, atol=1e-4)  # m
        np.testing.assert_allclose(a["speed"], b["speed"], rtol=0, atol=1e-4)          # m/s
        np.testing.assert_allclose(a["stop_prob"], b["stop_prob"], rtol=0, atol=1e-5)
        # the decision the agent takes from it: stop or go
        assert ((a["stop_prob"] > 0.5) == (b["stop_prob"] > 0.5)).all()


@pytest.mark.parametrize("name", SHIPPED[:1])
def test_onnx_is_deterministic_and_batch_independent(name):
    path = CHECKPOINTS / f"{name}.pt"
    p1, p2 = Policy(path), Policy(path)  # two sessions, as two worker processes would have
    bev, texts, speed, stopped = _inputs(5, 7)
    whole = p1(bev, texts, speed, stopped)
    again = p2(bev, texts, speed, stopped)
    for i in range(5):
        alone = p1(bev[i:i + 1], texts[i:i + 1], speed[i:i + 1], stopped[i:i + 1])
        for k in whole:
            assert np.array_equal(whole[k][i], alone[k][0]), k   # bitwise
    for k in whole:
        assert np.array_equal(whole[k], again[k]), k


def test_exported_graph_names_and_shapes():
    import onnx

    from icrsumo.learn.nets import BevLanguageNet, ModelConfig

    cfg = ModelConfig(encoder="ngram", buckets=64, width=4, hidden=8, lang=8, embed=4)
    model = BevLanguageNet(cfg).eval()
    graph = onnx.load_from_string(onnx_bytes(model)).graph
    assert tuple(i.name for i in graph.input) == INPUTS
    assert tuple(o.name for o in graph.output) == OUTPUTS
    fuse = OrtFuse(onnx_bytes(model))
    out = fuse(np.zeros((3, 7, 128, 128), np.uint8), np.zeros((3, 8), np.float32),
               np.zeros(3, np.float32), np.zeros(3, np.float32))
    assert out["waypoints"].shape == (3, 8, 2) and out["speed"].shape == out["stop_prob"].shape == (3,)
    assert ((out["stop_prob"] > 0) & (out["stop_prob"] < 1)).all()


def test_learned_agents_default_to_onnx_and_act_equals_act_batch():
    a, b = LearnedAgent("bev-ngram.pt"), LearnedAgent("bev-ngram.pt")
    assert a.runtime == "onnx" and a.policy.runtime == "onnx"
    assert LearnedAgent("bev-ngram.pt", runtime="torch").policy.runtime == "torch"
    from icrsumo.agents.base import EpisodeInfo, Observation

    bev, texts, speed, _ = _inputs(4, 3)
    obs = [Observation(t=0.1 * i, bev=bev[i], speed=float(speed[i]), instruction=texts[i],
                       instruction_id=i, notice="") for i in range(4)]
    for x in (a, b):
        x.reset(EpisodeInfo("r", "t", "n", 0.05, 0.1, 0))
    singles = [a.act(o) for o in obs]
    batched = [act_batch([b], [o])[0] for o in obs]
    for s, t in zip(singles, batched):
        np.testing.assert_array_equal(s.waypoints, t.waypoints)
        assert s.target_speed == t.target_speed


def test_unknown_runtime_is_an_input_error():
    with pytest.raises(InputError, match="unknown inference runtime"):
        Policy(CHECKPOINTS / "bev-ngram.pt", runtime="tensorrt")
