"""Training on CPU: a few steps lower the loss; the CLI trains, exports and resumes."""

import json
import re

import numpy as np
import pytest
import torch

from icrsumo.app.cli.main import main
from icrsumo.learn import nets
from icrsumo.learn.collect import CollectOptions, collect
from icrsumo.learn.train import TrainConfig, load_dataset

pytestmark = pytest.mark.sumo


@pytest.fixture(scope="module")
def tiny_data(converted, tmp_path_factory):
    out = tmp_path_factory.mktemp("collected")
    collect(CollectOptions(suite=str(converted["tiny"]), passes=2, every=4, limit=2), out, quiet=True)
    return out


def test_few_cpu_steps_lower_the_loss(tiny_data):
    ds = load_dataset(tiny_data)
    cfg = nets.ModelConfig(encoder="ngram", text_len=64, buckets=1024, width=8, hidden=64)
    enc = cfg.text_encoder()
    idx = np.arange(0, len(ds.speed), max(1, len(ds.speed) // 64))
    ids = enc.encode_many([ds.docs[d]["text"] for d in ds.doc[idx]])
    intents = [nets.INTENTS.index(ds.docs[d]["intent"]) if ds.docs[d]["intent"] in nets.INTENTS else 0
               for d in ds.doc[idx]]
    trainer = nets.Trainer(cfg, seed=0, lr=3e-3, weight_decay=0.0, steps=40, device=torch.device("cpu"))
    batch = trainer.to_device({"bev": ds.bev[idx], "ids": ids, "speed": ds.speed[idx],
                               "stopped_for": ds.stopped_for[idx], "waypoints": ds.waypoints[idx],
                               "target_speed": ds.target_speed[idx], "intent": np.array(intents)})
    before = trainer.evaluate(batch)["total"]
    for _ in range(25):
        trainer.train_step(batch)
    after = trainer.evaluate(batch)["total"]
    assert after < 0.7 * before


def test_initial_weights_depend_only_on_the_seed():
    cfg = nets.ModelConfig(encoder="token", vocab=("<pad>", "<unk>", "left"), width=8, hidden=32)
    state = torch.random.get_rng_state()
    a, b = nets.build_model(cfg, 3), nets.build_model(cfg, 3)
    assert torch.equal(torch.random.get_rng_state(), state)
    for (ka, va), (_, vb) in zip(a.state_dict().items(), b.state_dict().items()):
        assert torch.equal(va, vb), ka


def test_cli_trains_exports_and_resumes(tiny_data, tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text('encoder = "token"\nsteps = 6\nbatch = 16\neval_every = 2\ncheckpoint_every = 2\n'
                   'val_fraction = 0.3\nwidth = 8\nhidden = 32\ndevice = "cpu"\n')
    out = tmp_path / "run"
    assert main(["train", str(cfg), "--data", str(tiny_data), "--out", str(out), "--steps", "4"]) == 0
    err = capsys.readouterr().err  # progress on stderr: each stage, the steps with the loss, validation
    assert "icrsumo train: read " in err and "instruction texts (token encoder)" in err
    assert re.search(r"icrsumo train: +100%.*4/4 .*loss \d+\.\d{4}", err), err
    assert err.count('"val"') == 2
    log = [json.loads(x) for x in (out / "train_log.jsonl").read_text().splitlines()]
    assert [x["step"] for x in log] == [2, 4] and "val" in log[-1]
    ck = torch.load(out / "model.pt", weights_only=True)
    assert ck["format"] == nets.CHECKPOINT_FORMAT and ck["meta"]["steps"] == 4
    # same config, more steps: refused (config differs); same config reruns from last.pt
    assert main(["train", str(cfg), "--data", str(tiny_data), "--out", str(out), "--steps", "6"]) == 2
    assert "different config" in capsys.readouterr().err
    argv = ["train", str(cfg), "--data", str(tiny_data), "--out", str(out), "--steps", "4", "--quiet"]
    assert main(argv) == 0
    assert capsys.readouterr().err == ""
    assert [json.loads(x)["step"] for x in (out / "train_log.jsonl").read_text().splitlines()] == [2, 4]


def test_bad_config_is_one_line_error(tmp_path, capsys):
    cfg = tmp_path / "bad.toml"
    cfg.write_text('encoder = "bert"\n')
    assert main(["train", str(cfg), "--data", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "encoder" in err
    cfg.write_text('stepz = 3\n')
    assert main(["train", str(cfg), "--data", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert "unknown key" in capsys.readouterr().err


def test_augmented_training_config(tiny_data):
    from icrsumo.learn.train import text_pool

    ds = load_dataset(tiny_data)
    pool = text_pool(ds, TrainConfig(augment_instructions=True, variants=8), np.random.default_rng(0))
    assert all(len(p) == 8 for p, d in zip(pool, ds.docs) if d["type"] != "none")
    assert any(len(set(p)) > 3 for p in pool)


def test_the_pretrained_encoder_trains_and_drives(tiny_data, tmp_path):
    """bev-minilm's recipe on CPU: the frozen sentence embeddings of the training texts, an MLP
    over them, a checkpoint a LearnedAgent drives with (ONNX Runtime for both networks)."""
    from icrsumo.agents.base import Observation
    from icrsumo.learn.agent import LearnedAgent
    from icrsumo.learn.minilm import DIM, encoder

    cfg = tmp_path / "m.toml"
    cfg.write_text('encoder = "minilm"\naugment_instructions = true\nvariants = 3\nsteps = 4\nbatch = 16\n'
                   'eval_every = 2\ncheckpoint_every = 2\nval_fraction = 0.3\nwidth = 8\nhidden = 32\n'
                   'device = "cpu"\n')
    out = tmp_path / "run"
    assert main(["train", str(cfg), "--data", str(tiny_data), "--out", str(out), "--workers", "2"]) == 0
    ck = torch.load(out / "model.pt", weights_only=True)
    assert ck["config"]["encoder"] == "minilm" and ck["config"]["text_len"] == DIM
    agent = LearnedAgent(out / "model.pt")
    bev = np.zeros((7, 128, 128), np.uint8)
    obs = Observation(t=0.0, bev=bev, speed=3.0, instruction="Turn left at the junction.", instruction_id=0,
                      notice="")
    a, b = agent.act(obs), LearnedAgent(out / "model.pt").act(obs)
    assert np.array_equal(a.waypoints, b.waypoints) and a.target_speed == b.target_speed
    e = encoder().embed("Turn left at the junction.")
    assert e.shape == (DIM,) and abs(float(e @ e) - 1.0) < 1e-4
    near, far = encoder().embed("Take a left at the junction."), encoder().embed("Stop here.")
    assert float(e @ near) > float(e @ far)


def test_the_tuned_encoder_starts_at_the_pretrained_layer_and_trains_it(tiny_data, tmp_path):
    """bev-minilm-tuned's recipe on CPU: token states of the training texts, the encoder's last
    layer copied into the network at the start and trained at its own (lower) learning rate."""
    from icrsumo.agents.base import Observation
    from icrsumo.learn import nets
    from icrsumo.learn.agent import LearnedAgent
    from icrsumo.learn.minilm import encoder

    mcfg = nets.ModelConfig(encoder="minilm-tuned", text_len=8 * 384, width=8, hidden=32)
    start = {k: v.numpy() for k, v in nets.build_model(mcfg, 0).lang.layer.state_dict().items()}
    assert all(np.array_equal(start[k], v) for k, v in encoder().last_layer().items())
    trainer = nets.Trainer(mcfg, 0, 1e-3, 0.0, 10, torch.device("cpu"), lr_tuned=2e-5)
    lrs = [g["lr"] for g in trainer.opt.param_groups]   # one schedule, two peaks
    assert len(lrs) == 2 and lrs[1] / lrs[0] == pytest.approx(2e-5 / 1e-3)
    cfg = tmp_path / "m.toml"
    cfg.write_text('encoder = "minilm-tuned"\naugment_instructions = true\nvariants = 2\nsteps = 3\n'
                   'batch = 8\neval_every = 3\ncheckpoint_every = 3\nval_fraction = 0.3\nwidth = 8\n'
                   'hidden = 32\ndevice = "cpu"\nlr_tuned = 0.001\n')
    out = tmp_path / "run"
    assert main(["train", str(cfg), "--data", str(tiny_data), "--out", str(out)]) == 0
    ck = torch.load(out / "model.pt", weights_only=True)
    assert ck["config"]["encoder"] == "minilm-tuned" and ck["config"]["text_len"] == 64 * 384
    assert not np.array_equal(ck["model"]["lang.layer.q_w"].numpy(), start["q_w"])
    bev = np.zeros((7, 128, 128), np.uint8)
    obs = Observation(t=0.0, bev=bev, speed=3.0, instruction="Keep left at the fork.", instruction_id=0,
                      notice="")
    a, b = LearnedAgent(out / "model.pt").act(obs), LearnedAgent(out / "model.pt").act(obs)
    assert np.array_equal(a.waypoints, b.waypoints) and a.target_speed == b.target_speed


def test_a_tuned_checkpoint_with_a_partial_token_state_is_refused(tmp_path):
    from icrsumo.core.errors import InputError
    from icrsumo.learn import nets

    with pytest.raises(InputError, match="config.text_len: 400 is not a whole number of 384-value"):
        nets.config_from_dict({"encoder": "minilm-tuned", "text_len": 400}, tmp_path / "m.pt")


def test_a_minilm_config_with_another_text_len_is_refused(tmp_path):
    from icrsumo.core.errors import InputError
    from icrsumo.learn.train import read_config

    cfg = tmp_path / "m.toml"
    cfg.write_text('encoder = "minilm"\ntext_len = 64\n')
    with pytest.raises(InputError, match="vector has 384 values, not 64"):
        read_config(cfg).check()
