"""Bad input on the training side is one InputError line naming the file, the place and the fix,
never a traceback, and a refused ``icrsumo train`` / ``icrsumo collect`` writes nothing.

No SUMO here: the collected data are synthetic episode files in collect's layout, and the one
real training run is two steps of a tiny model on CPU."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from icrsumo.app.cli.main import main
from icrsumo.core.errors import Field, InputError
from icrsumo.learn import nets
from icrsumo.learn.agent import CHECKPOINTS, LearnedAgent
from icrsumo.learn.collect import COLLECT_FORMAT, CollectOptions, collect
from icrsumo.learn.labels import ARC_M
from icrsumo.learn.train import TrainConfig, load_dataset, read_config, split, train

SHIPPED = CHECKPOINTS / "bev-ngram.pt"
TINY = ('encoder = "ngram"\nsteps = 2\nbatch = 4\neval_every = 1\ncheckpoint_every = 1\n'
        'val_fraction = 0.3\ntext_len = 16\nbuckets = 64\nwidth = 4\nhidden = 16\nlr = 0.001\n'
        'device = "cpu"\n')


# --------------------------------------------------------------------------- helpers
def _episode(path: Path, n: int = 6, seed: int = 0, **override: object) -> None:
    rng = np.random.default_rng(seed)
    docs = [{"id": 0, "text": "Turn left at the next junction.", "type": "turn", "intent": "left",
             "distance": 30.0, "slots": {"dir": "left"}},
            {"id": 1, "text": "Follow the road.", "type": "follow", "intent": "follow", "distance": None,
             "slots": {}}]
    arrays = {
        "bev": rng.integers(0, 256, size=(n, 7, 128, 16), dtype=np.uint8),
        "speed": rng.uniform(0, 8, n).astype(np.float32),
        "instruction": np.array([-1] + [i % 2 for i in range(n - 1)], dtype=np.int16),
        "waypoints": np.stack([np.stack([ARC_M, np.zeros_like(ARC_M)], 1)] * n).astype(np.float32),
        "target_speed": rng.uniform(0, 8, n).astype(np.float32),
        "perturbed": np.zeros(n, dtype=np.uint8),
        "t": np.arange(n, dtype=np.float32) * 0.2,
        "stopped_for": np.zeros(n, dtype=np.float32),
        "instructions": np.asarray(json.dumps(docs)),
    }
    arrays.update(override)
    arrays = {k: v for k, v in arrays.items() if v is not None}
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **arrays)


def _data(folder: Path, routes: int = 3) -> Path:
    """A folder in ``icrsumo collect``'s layout with ``routes`` routes of one pass each."""
    names = [f"route_{i:02d}__p0.npz" for i in range(routes)]
    for i, name in enumerate(names):
        _episode(folder / "episodes" / name, seed=i)
    (folder / "collect.json").write_text(json.dumps({"format": COLLECT_FORMAT, "config": {},
                                                     "frames": 6 * routes, "episodes": names}))
    return folder


def _listing(folder: Path) -> dict[str, int]:
    return {str(p.relative_to(folder)): p.stat().st_mtime_ns for p in sorted(folder.rglob("*"))}


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    return _data(tmp_path_factory.mktemp("collected"))


@pytest.fixture(scope="module")
def run(data, tmp_path_factory) -> tuple[Path, Path]:
    """A real two-step training run: (its config file, its out folder with last.pt and model.pt)."""
    d = tmp_path_factory.mktemp("run")
    cfg = d / "tiny.toml"
    cfg.write_text(TINY)
    out = d / "out"
    train(read_config(cfg), data, out, quiet=True)
    assert (out / "last.pt").is_file() and (out / "model.pt").is_file()
    return cfg, out


def _raises(fn, file: Path | str | Field, *words: str) -> InputError:
    with pytest.raises(InputError) as info:
        fn()
    err = info.value
    line = err.line()
    assert err.field == file.name if isinstance(file, Field) else err.file == str(file), line
    assert "\n" not in line and err.fix, line
    for w in words:
        assert w in line, line
    return err


# --------------------------------------------------------------------------- 1. training config
CONFIGS = {
    "utf16": ("steps = 3\n".encode("utf-16"), ["UTF-16-encoded, not UTF-8"]),
    "utf16-no-bom": ("steps = 3\n".encode("utf-16-le"), ["NUL bytes", "line 1"]),
    "latin1": ('encoder = "ngr\u00e4m"\n'.encode("latin-1"), ["not UTF-8", "line 1"]),
    "syntax": (b"steps = 3\nbatch =\n", ["line 2, column", "not valid TOML"]),
    "string-for-int": (b'steps = "10"\n', ["line 1 (steps)", "must be an integer, not str"]),
    "list-for-int": (b"batch = [1, 2]\n", ["line 1 (batch)", "must be an integer, not list"]),
    "float-for-int": (b"steps = 1e3\n", ["must be an integer, not float"]),
    "bool-for-int": (b"seed = true\n", ["must be an integer, not bool"]),
    "table-for-float": (b"steps = 3\n[lr]\nmax = 1\n", ["line 2 (lr)", "must be a number, not dict"]),
    "string-for-float": (b'lr = "fast"\n', ["must be a number, not str", "lr = 0.001"]),
    "int-for-bool": (b"augment_instructions = 1\n", ["must be true or false, not int"]),
    "int-for-str": (b"device = 0\n", ["must be a string, not int"]),
    "unknown-key": (b"steps = 3\nstepz = 3\n", ["line 2 (stepz)", "unknown key 'stepz'",
                                                "did you mean steps"]),
    "nan-lr": (b"lr = nan\n", ["lr must be a finite number, not nan"]),
    "inf-lr": (b"lr = inf\n", ["lr must be a finite number, not inf"]),
    "negative-lr": (b"lr = -1\n", ["lr must be positive, not -1.0"]),
    "zero-lr": (b"lr = 0.0\n", ["lr must be positive"]),
    "nan-val-fraction": (b"val_fraction = nan\n", ["val_fraction"]),
    "zero-steps": (b"steps = 0\n", ["steps must be 1 to 100,000,000, not 0"]),
    "negative-batch": (b"batch = -5\n", ["batch must be 1 to 65,536, not -5"]),
    "huge-batch": (b"batch = 1000000000000\n", ["batch must be 1 to 65,536, not 1000000000000"]),
    "negative-seed": (b"seed = -1\n", ["seed -1 out of range"]),
    "one-bucket": (b"buckets = 1\n", ["buckets must be 2 to"]),
    "negative-decay": (b"weight_decay = -0.1\n", ["weight_decay must not be negative"]),
    "val-fraction": (b"val_fraction = 0.7\n", ["val_fraction 0.7 out of range"]),
    "probability": (b"p_noise = 2\n", ["p_noise 2.0 is not a probability"]),
    "encoder": (b'encoder = "bert"\n', ["unknown encoder 'bert'", "token, ngram"]),
    "device-tpu": (b'device = "tpu"\n', ["line 1 (device)", "device 'tpu': unknown device"]),
    "device-cuda99": (b'device = "cuda:99"\n', ["device 'cuda:99': this machine has"]),
    "device-empty": (b'device = ""\n', ["device '': unknown device"]),
}


@pytest.mark.parametrize("name", CONFIGS)
def test_bad_training_config_is_one_input_error(name, tmp_path):
    content, words = CONFIGS[name]
    path = tmp_path / f"{name}.toml"
    path.write_bytes(content)
    _raises(lambda: read_config(path), path, *words)


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has CUDA")
def test_cuda_device_without_cuda(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('device = "cuda"\n')
    _raises(lambda: read_config(path), path, "device 'cuda': this machine has no CUDA device",
            "use cpu or auto")
    _raises(lambda: read_config(tmp_path / "c.toml", device="cuda:0"), Field("device"), "no CUDA device")


@pytest.mark.parametrize(("make", "words"), [
    (lambda p: p, ["training config not found"]),
    (lambda p: p.mkdir() or p, ["is a folder, not a file (training config)"]),
])
def test_config_path_that_is_no_file(make, words, tmp_path):
    path = make(tmp_path / "missing.toml")
    _raises(lambda: read_config(path), path, *words)


@pytest.mark.parametrize(("override", "words"), [
    ({"steps": 0}, ["steps must be 1 to 100,000,000, not 0"]),
    ({"seed": -3}, ["seed -3 out of range"]),
    ({"device": "tpu"}, ["device 'tpu': unknown device"]),
    ({"device": "cuda:99"}, ["device 'cuda:99': this machine has"]),
])
def test_bad_override_names_its_field(override, words, tmp_path):
    """A value given beside the config (the command line's --steps, ...) is named by its field
    (the CLI names its option: test_cli_train_refuses_in_one_line_and_writes_nothing)."""
    path = tmp_path / "c.toml"
    path.write_text(TINY)
    err = _raises(lambda: read_config(path, **override), Field(*override), *words)
    assert err.place == ""


def test_config_built_in_python_is_checked_by_train(data, tmp_path):
    _raises(lambda: train(TrainConfig(lr=float("nan")), data, tmp_path / "o"), "train config", "lr")
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- 2. checkpoints
def _save(obj: object, path: Path) -> Path:
    torch.save(obj, path)
    return path


class Hostile:
    """Unpickling this would run a shell command: weights_only=True refuses it."""

    def __init__(self, marker: str) -> None:
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


class Custom:
    pass


def _shipped() -> dict:
    return torch.load(SHIPPED, map_location="cpu", weights_only=True)


def _bad_checkpoints(tmp: Path) -> dict[str, tuple[Path, list[str]]]:
    raw = SHIPPED.read_bytes()
    cases: dict[str, tuple[Path, list[str]]] = {}

    def write(name: str, data: bytes) -> Path:
        p = tmp / f"{name}.pt"
        p.write_bytes(data)
        return p

    cases["empty"] = (write("empty", b""), ["is empty (0 bytes)"])
    cases["truncated-half"] = (write("half", raw[: len(raw) // 2]), ["truncated or not a torch file"])
    cases["truncated-head"] = (write("head", raw[:100]), ["truncated or not a torch file"])
    cases["text"] = (write("text", b"these are not weights\n"), ["not a torch file"])
    np.savez(tmp / "arrays.npz", a=np.zeros(3))
    cases["npz"] = (tmp / "arrays.npz", ["not an icrsumo exact checkpoint"])
    cases["hostile-pickle"] = (_save(Hostile(str(tmp / "pwned")), tmp / "hostile.pt"),
                               ["refused by torch.load(weights_only=True)", "posix.system"])
    cases["custom-class"] = (_save({"format": nets.CHECKPOINT_FORMAT, "x": Custom()}, tmp / "custom.pt"),
                             ["refused by torch.load(weights_only=True)", "Custom"])
    cases["numpy-array"] = (_save({"model": np.zeros(3)}, tmp / "numpy.pt"), ["refused by torch.load"])
    cases["list"] = (_save([1, 2, 3], tmp / "list.pt"), ["holds a list, not an icrsumo checkpoint"])
    cases["no-format"] = (_save({"model": {}}, tmp / "noformat.pt"),
                          ["format: not an icrsumo agent checkpoint"])
    ck = _shipped()
    ck["config"] = dict(ck["config"], encoder="bert")
    cases["bad-encoder"] = (_save(ck, tmp / "encoder.pt"), ["config.encoder: unknown encoder 'bert'"])
    ck = _shipped()
    ck["config"] = dict(ck["config"], width="wide")
    cases["config-type"] = (_save(ck, tmp / "ctype.pt"),
                            ["config.width: the value must be an integer, not str"])
    ck = _shipped()
    ck["config"] = dict(ck["config"], depth=3)
    cases["config-key"] = (_save(ck, tmp / "ckey.pt"), ["config.depth: unknown model option"])
    ck = _shipped()
    ck["config"] = "ngram"
    cases["config-not-dict"] = (_save(ck, tmp / "cnotdict.pt"),
                                ["config: the model config must be an object"])
    ck = _shipped()
    ck["model"]["head.weight"] = torch.zeros(3, 3)
    cases["wrong-shape"] = (_save(ck, tmp / "shape.pt"), ["model.head.weight: shape (3, 3) does not fit"])
    ck = _shipped()
    del ck["model"]["fc.bias"]
    ck["model"]["extra.weight"] = torch.zeros(1)
    cases["wrong-keys"] = (_save(ck, tmp / "keys.pt"),
                           ["1 missing (e.g. fc.bias)", "1 unexpected (e.g. extra.weight)"])
    ck = _shipped()
    ck["config"] = dict(ck["config"], width=64)
    cases["config-mismatch"] = (_save(ck, tmp / "mismatch.pt"), ["does not fit the model config"])
    ck = _shipped()
    ck["model"]["fc.bias"] = [0.0] * 256
    cases["not-a-tensor"] = (_save(ck, tmp / "nottensor.pt"),
                             ["model.fc.bias: is a list, not a floating-point tensor"])
    ck = _shipped()
    ck["model"] = None
    cases["no-weights"] = (_save(ck, tmp / "noweights.pt"),
                           ["model: the weights must be an object, not null"])
    return cases


BAD_CHECKPOINTS = ["empty", "truncated-half", "truncated-head", "text", "npz", "hostile-pickle",
                   "custom-class", "numpy-array", "list", "no-format", "bad-encoder", "config-type",
                   "config-key", "config-not-dict", "wrong-shape", "wrong-keys", "config-mismatch",
                   "not-a-tensor", "no-weights"]


@pytest.fixture(scope="module")
def bad_checkpoints(tmp_path_factory) -> dict[str, tuple[Path, list[str]]]:
    return _bad_checkpoints(tmp_path_factory.mktemp("checkpoints"))


@pytest.mark.parametrize("name", BAD_CHECKPOINTS)
def test_bad_agent_checkpoint_is_one_input_error(name, bad_checkpoints):
    path, words = bad_checkpoints[name]
    _raises(lambda: LearnedAgent(path), path, *words)
    assert not (path.parent / "pwned").exists()   # nothing in the file ran


def test_agent_checkpoint_path_and_device(tmp_path, run):
    _raises(lambda: LearnedAgent(tmp_path / "nope.pt"), tmp_path / "nope.pt", "agent checkpoint not found",
            "bev-token")
    _raises(lambda: LearnedAgent(tmp_path), tmp_path, "is a folder")
    _raises(lambda: LearnedAgent(SHIPPED, device="tpu"), "device", "device 'tpu': unknown device")
    last = run[1] / "last.pt"
    _raises(lambda: LearnedAgent(last), last, "format 'icrsumo-agent/1+train'", "use the model.pt beside it")
    agent = LearnedAgent(run[1] / "model.pt")          # the run's own export loads
    assert agent.policy.cfg.width == 4


# --------------------------------------------------------------------------- 2b. resuming from OUT/last.pt
def _bad_states(last: Path, tmp: Path) -> dict[str, tuple[bytes, list[str]]]:
    raw = last.read_bytes()
    state = torch.load(last, map_location="cpu", weights_only=True)

    def saved(obj: object) -> bytes:
        p = tmp / "state.pt"
        torch.save(obj, p)
        return p.read_bytes()

    other_shape = dict(state, model=dict(state["model"], **{"fc.weight": torch.zeros(2, 2)}))
    bad_opt = dict(state, opt={"state": {0: {"exp_avg": torch.zeros(5)}}, "param_groups": []})
    return {
        "empty": (b"", ["training checkpoint is empty"]),
        "truncated": (raw[: len(raw) * 2 // 3], ["training checkpoint is truncated or not a torch file"]),
        "hostile": (saved(Hostile(str(tmp / "pwned"))), ["refused by torch.load(weights_only=True)"]),
        "custom": (saved(dict(state, extra=Custom())), ["refused by torch.load(weights_only=True)"]),
        "model-pt": (saved(torch.load(last.parent / "model.pt", weights_only=True)),
                     ["format: not an icrsumo training checkpoint"]),
        "other-config": (saved(dict(state, train_config=dict(state["train_config"], lr=0.5))),
                         ["train_config: was written with a different config"]),
        "wrong-shape": (saved(other_shape), ["model.fc.weight: shape (2, 2) does not fit"]),
        "bad-step": (saved(dict(state, step=10**6)), ["step: step 1000000 is outside 0..2"]),
        "bad-opt": (saved(bad_opt), ["opt.state[0].exp_avg: does not fit"]),
        "bad-rng": (saved(dict(state, rng={"bit_generator": "MT19937"})),
                    ["rng: not a random generator state"]),
    }


RESUME_CASES = ["empty", "truncated", "hostile", "custom", "model-pt", "other-config", "wrong-shape",
                "bad-step", "bad-opt", "bad-rng"]


@pytest.mark.parametrize("name", RESUME_CASES)
def test_bad_resume_checkpoint_is_refused_before_writing(name, run, data, tmp_path):
    cfg_path, done = run
    content, words = _bad_states(done / "last.pt", tmp_path)[name]
    out = tmp_path / "out"
    shutil.copytree(done, out)
    (out / "last.pt").write_bytes(content)
    before = _listing(out)
    _raises(lambda: train(read_config(cfg_path), data, out, quiet=True), out / "last.pt", *words)
    assert _listing(out) == before
    assert not (tmp_path / "pwned").exists()


def test_damaged_train_log_on_resume(run, data, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(run[1], out)
    (out / "train_log.jsonl").write_text('{"step": 1}\nnot json\n')
    _raises(lambda: train(read_config(run[0]), data, out, quiet=True), out / "train_log.jsonl", "line 2",
            "not a JSON line with a step")


def test_good_run_resumes(run, data, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(run[1], out)
    train(read_config(run[0]), data, out, quiet=True)   # finished: nothing redone, nothing refused
    assert [json.loads(x)["step"] for x in (out / "train_log.jsonl").read_text().splitlines()] == [1, 2]


# --------------------------------------------------------------------------- 4. data folders
def _bad_data(tmp: Path) -> dict[str, tuple[Path, Path, list[str]]]:
    """name -> (the --data folder, the file the error names, words of the message)."""
    cases = {}

    def folder(name: str) -> Path:
        return _data(tmp / name, routes=2)

    d = tmp / "missing"
    cases["missing-folder"] = (d, d, ["data folder not found"])
    f = tmp / "a-file"
    f.write_text("x")
    cases["file-not-folder"] = (f, f, ["is not a folder"])
    d = tmp / "not-collect"
    d.mkdir()
    cases["no-manifest"] = (d, d, ["collect.json: no collected data here"])
    d = folder("not-json")
    (d / "collect.json").write_text('{"format": "icrsumo-collect/1", "episodes": [\n')
    cases["manifest-not-json"] = (d, d / "collect.json", ["line 2, column 1: malformed JSON"])
    d = folder("utf16")
    (d / "collect.json").write_bytes(json.dumps({"format": COLLECT_FORMAT, "episodes": []}).encode("utf-16"))
    cases["manifest-utf16"] = (d, d / "collect.json", ["UTF-16-encoded"])
    d = folder("format")
    (d / "collect.json").write_text('{"format": "icrsumo-index/1", "episodes": []}')
    cases["manifest-format"] = (d, d / "collect.json", ["format: unsupported format 'icrsumo-index/1'"])
    d = folder("episodes-type")
    (d / "collect.json").write_text('{"format": "icrsumo-collect/1", "episodes": "all"}')
    cases["episodes-not-list"] = (d, d / "collect.json",
                                  ["episodes: the episode list must be a list, not str"])
    d = folder("empty")
    (d / "collect.json").write_text('{"format": "icrsumo-collect/1", "episodes": []}')
    cases["no-episodes"] = (d, d / "collect.json", ["episodes: lists no episodes"])
    d = folder("escape")
    (d / "collect.json").write_text('{"format": "icrsumo-collect/1", "episodes": ["../../etc.npz"]}')
    cases["episode-path"] = (d, d / "collect.json", ["episodes[0]", "is not an episode file name"])
    d = folder("gone")
    (d / "episodes" / "route_01__p0.npz").unlink()
    cases["episode-missing"] = (d, d / "episodes" / "route_01__p0.npz", ["episode file not found"])
    d = folder("truncated")
    ep = d / "episodes" / "route_01__p0.npz"
    ep.write_bytes(ep.read_bytes()[:500])
    cases["episode-truncated"] = (d, ep, ["episode file is truncated or damaged (BadZipFile"])
    d = folder("zero")
    ep = d / "episodes" / "route_00__p0.npz"
    ep.write_bytes(b"")
    cases["episode-empty"] = (d, ep, ["episode file is empty (0 bytes)"])
    d = folder("text")
    ep = d / "episodes" / "route_00__p0.npz"
    ep.write_text("frames\n")
    cases["episode-text"] = (d, ep, ["is not an episode file (not an .npz archive)"])
    d = folder("npy")
    ep = d / "episodes" / "route_00__p0.npz"
    with open(ep, "wb") as fh:
        np.save(fh, np.zeros(3))
    cases["episode-npy"] = (d, ep, ["not an .npz archive"])
    d = folder("pickled")
    ep = d / "episodes" / "route_00__p0.npz"
    _episode(ep, instructions=np.array([{"text": "hi"}], dtype=object))
    cases["episode-object-array"] = (d, ep, ["truncated or damaged (ValueError: Object arrays cannot"])
    d = folder("lacks")
    _episode(d / "episodes" / "route_00__p0.npz", waypoints=None)
    cases["episode-lacks-key"] = (d, d / "episodes" / "route_00__p0.npz", ["episode file lacks waypoints"])
    d = folder("shape")
    _episode(d / "episodes" / "route_00__p0.npz", bev=np.zeros((6, 7, 64, 8), np.uint8))
    cases["episode-bev-shape"] = (d, d / "episodes" / "route_00__p0.npz",
                                  ["bev: array of shape (6, 7, 64, 8)"])
    d = folder("frames")
    _episode(d / "episodes" / "route_00__p0.npz", speed=np.zeros(4, np.float32))
    cases["episode-lengths"] = (d, d / "episodes" / "route_00__p0.npz",
                                ["speed: array of shape (4,) and dtype float32, not (6,) floats"])
    d = folder("nan")
    wps = np.zeros((6, len(ARC_M), 2), np.float32)
    wps[2, 3, 0] = np.nan
    _episode(d / "episodes" / "route_00__p0.npz", waypoints=wps)
    cases["episode-nan"] = (d, d / "episodes" / "route_00__p0.npz", ["waypoints: holds non-finite values"])
    d = folder("index")
    _episode(d / "episodes" / "route_00__p0.npz", instruction=np.array([0, 1, 2, 5, 1, 0], np.int16))
    cases["instruction-index"] = (d, d / "episodes" / "route_00__p0.npz",
                                  ["instruction: indices outside -1..1"])
    d = folder("docs")
    _episode(d / "episodes" / "route_00__p0.npz", instructions=np.asarray("[{"))
    cases["instructions-json"] = (d, d / "episodes" / "route_00__p0.npz", ["instructions: malformed JSON"])
    d = folder("doc-type")
    _episode(d / "episodes" / "route_00__p0.npz", instructions=np.asarray('[{"text": 3}]'))
    cases["instruction-doc"] = (d, d / "episodes" / "route_00__p0.npz",
                                ["instructions[0].text: text must be a string, not int"])
    return cases


BAD_DATA = ["missing-folder", "file-not-folder", "no-manifest", "manifest-not-json", "manifest-utf16",
            "manifest-format", "episodes-not-list", "no-episodes", "episode-path", "episode-missing",
            "episode-truncated", "episode-empty", "episode-text", "episode-npy", "episode-object-array",
            "episode-lacks-key", "episode-bev-shape", "episode-lengths", "episode-nan", "instruction-index",
            "instructions-json", "instruction-doc"]


@pytest.fixture(scope="module")
def bad_data(tmp_path_factory):
    return _bad_data(tmp_path_factory.mktemp("bad_data"))


@pytest.mark.parametrize("name", BAD_DATA)
def test_bad_data_folder_is_one_input_error(name, bad_data):
    folder, file, words = bad_data[name]
    _raises(lambda: load_dataset(folder), file, *words)


def test_every_route_in_validation(tmp_path):
    d = _data(tmp_path / "one", routes=1)
    ds = load_dataset(d)
    # a seed whose hash puts the only route in the validation split
    seed = next(s for s in range(200) if not len(split(ds, 0.49, s)[0]))
    cfg = TrainConfig(val_fraction=0.49, seed=seed, steps=1, batch=2, width=4, hidden=8, buckets=64,
                      text_len=8, device="cpu")
    _raises(lambda: train(cfg, d, tmp_path / "o", quiet=True), d, "fall in the validation split")
    assert not (tmp_path / "o").exists()


# -------------------------------------------------------------------------- 3. CLI: one line, nothing written
def _cli(argv: list[str], capsys) -> str:
    assert main(argv) == 2
    cap = capsys.readouterr()
    assert cap.out == ""
    lines = cap.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("icrsumo: error: "), cap.err
    return lines[0]


@pytest.mark.parametrize(("case", "extra", "words"), [
    ("nan-lr", [], ["lr must be a finite number, not nan"]),
    ("utf16", [], ["UTF-16-encoded"]),
    ("tpu", ["--device", "tpu"], ["--device: device 'tpu': unknown device"]),
    ("zero-steps", ["--steps", "0"], ["--steps: steps must be 1 to"]),
    ("missing-data", [], ["data folder not found"]),
    ("bad-manifest", [], ["collect.json: line 1, column 2: malformed JSON"]),
    ("truncated-episode", [], ["route_01__p0.npz: episode file is truncated or damaged"]),
])
def test_cli_train_refuses_in_one_line_and_writes_nothing(case, extra, words, data, tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(TINY.replace("lr = 0.001", "lr = nan") if case == "nan-lr" else TINY)
    if case == "utf16":
        cfg.write_bytes(TINY.encode("utf-16"))
    d = data
    if case == "missing-data":
        d = tmp_path / "nowhere"
    elif case in ("bad-manifest", "truncated-episode"):
        d = tmp_path / "data"
        shutil.copytree(data, d)
        if case == "bad-manifest":
            (d / "collect.json").write_text("{oops")
        else:
            ep = d / "episodes" / "route_01__p0.npz"
            ep.write_bytes(ep.read_bytes()[:-200])
    out = tmp_path / "run" / "out"
    line = _cli(["train", str(cfg), "--data", str(d), "--out", str(out), *extra], capsys)
    for w in words:
        assert w in line, line
    assert not out.exists() and not out.parent.exists()


def test_cli_train_refuses_a_hostile_last_pt(run, data, tmp_path, capsys):
    out = tmp_path / "out"
    shutil.copytree(run[1], out)
    torch.save(Hostile(str(tmp_path / "pwned")), out / "last.pt")
    before = _listing(out)
    line = _cli(["train", str(run[0]), "--data", str(data), "--out", str(out)], capsys)
    assert f"{out / 'last.pt'}: training checkpoint refused by torch.load(weights_only=True)" in line
    assert _listing(out) == before and not (tmp_path / "pwned").exists()


def test_cli_train_runs_with_a_good_config(data, tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(TINY)
    out = tmp_path / "out"
    assert main(["train", str(cfg), "--data", str(data), "--out", str(out), "--steps", "1"]) == 0
    assert (out / "model.pt").is_file()


@pytest.mark.parametrize(("extra", "words"), [
    (["--seed", "-1"], ["--seed: -1: out of range"]),
    (["--limit", "-2"], ["--limit: -2 is negative"]),
    (["--driver", "route-oracle"], ["--driver: route-oracle: is a privileged agent"]),
    (["--driver", "NOPE.pt"], ["NOPE.pt: agent checkpoint not found"]),
    (["--driver", "HOSTILE"], ["refused by torch.load(weights_only=True)"]),
    (["--driver", "TRUNCATED"], ["agent checkpoint is truncated or not a torch file"]),
    (["--suite", "tiny"], ["is an evaluation split"]),
    (["--suite", "no-such-routes.xml"], ["no such route file or bundled split"]),
])
def test_cli_collect_refuses_in_one_line_and_writes_nothing(extra, words, tmp_path, capsys):
    if "HOSTILE" in extra:
        extra = ["--driver", str(_save(Hostile(str(tmp_path / "pwned")), tmp_path / "h.pt"))]
    if "TRUNCATED" in extra:
        (tmp_path / "t.pt").write_bytes(SHIPPED.read_bytes()[:4096])
        extra = ["--driver", str(tmp_path / "t.pt")]
    if "NOPE.pt" in extra:
        extra = ["--driver", str(tmp_path / "NOPE.pt")]
    out = tmp_path / "out"
    line = _cli(["collect", "--out", str(out), "--workers", "1", *extra], capsys)
    for w in words:
        assert w in line, line
    assert not out.exists() and not (tmp_path / "pwned").exists()


def test_collect_refuses_a_damaged_manifest(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "collect.json").write_text('{"format": "icrsumo-collect/1",')
    before = _listing(out)
    _raises(lambda: collect(CollectOptions(), out, quiet=True), out / "collect.json", "malformed JSON")
    assert _listing(out) == before
