"""``icrsumo train``: behaviour cloning of the expert's plan from ``icrsumo collect`` data.

Config: a TOML file of :class:`TrainConfig` keys (unknown keys are refused). Seeded: the
initial weights, the validation split (by route), the batch order and the instruction
augmentation all follow ``seed`` through ``numpy.random.Generator`` objects (and a forked torch
RNG for the initial weights). Every ``eval_every`` steps one JSON line with the mean training
losses since the last line and the validation metrics goes to ``OUT/train_log.jsonl`` (and to
stderr); every ``checkpoint_every`` steps the whole state goes to ``OUT/last.pt``, from which a
rerun with the same config resumes. At the end the inference checkpoint ``OUT/model.pt`` is
exported (float32, loaded with ``torch.load(..., weights_only=True)``).

Runs on CPU (slowly) or on a GPU (``device = "auto"`` picks CUDA when present); the whole
dataset (bit-packed rasters) is moved to the device once, so a GPU is never starved.
"""

from __future__ import annotations

import json
import sys
import time
import tomllib
import zlib
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..fsio import dumps_json, write_atomic
from .augment import augment
from .text import ENCODERS, build_vocab

TRAIN_FORMAT = "icrsumo-train/1"
_DEFAULT_TEXT_LEN = {"token": 32, "ngram": 192}


@dataclass(frozen=True)
class TrainConfig:
    """Training options (TOML keys). Sizes in frames; ``lr`` peak of a one-cycle schedule;
    ``val_fraction`` of routes held out; ``variants`` augmented texts drawn per instruction."""

    encoder: str = "ngram"
    augment_instructions: bool = False
    seed: int = 0
    steps: int = 20000
    batch: int = 256
    lr: float = 1e-3
    weight_decay: float = 1e-4
    eval_every: int = 500
    checkpoint_every: int = 1000
    val_fraction: float = 0.05
    text_len: int = 0
    buckets: int = 8192
    width: int = 32
    hidden: int = 256
    p_paraphrase: float = 0.5
    p_noise: float = 0.3
    variants: int = 24
    device: str = "auto"

    def check(self, where: str) -> None:
        if self.encoder not in ENCODERS:
            raise InputError(where, "encoder", f"unknown encoder {self.encoder!r}",
                             f"use one of {', '.join(ENCODERS)}")
        for name in ("steps", "batch", "eval_every", "checkpoint_every", "buckets", "width", "hidden",
                     "variants"):
            if getattr(self, name) < 1:
                raise InputError(where, name, "must be at least 1", "give a positive number")
        if not 0.0 <= self.val_fraction < 0.5:
            raise InputError(where, "val_fraction", f"{self.val_fraction} out of range", "use 0 to 0.5")


def read_config(path: Path, **overrides: object) -> TrainConfig:
    """Read a TOML config; ``overrides`` (non-None) replace its values."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(path, "", "no such file", "give the path of a TOML training config") from None
    except tomllib.TOMLDecodeError as err:
        raise InputError(path, "", f"not valid TOML ({err})", "fix the syntax") from None
    known = {f.name: f.type for f in fields(TrainConfig)}
    for key, value in raw.items():
        if key not in known:
            raise InputError(path, key, "unknown key", f"use some of {', '.join(known)}")
        default = getattr(TrainConfig(), key)
        if isinstance(default, bool) != isinstance(value, bool) or (
                not isinstance(value, type(default)) and not (isinstance(default, float)
                                                               and isinstance(value, int))):
            raise InputError(path, key, f"{value!r} is not a {type(default).__name__}",
                             "fix the value's type")
    raw.update({k: v for k, v in overrides.items() if v is not None})
    if isinstance(raw.get("lr"), int):
        raw["lr"] = float(raw["lr"])
    cfg = TrainConfig(**raw)
    cfg.check(str(path))
    return cfg


# --------------------------------------------------------------------------- data
@dataclass
class Dataset:
    """Every collected frame in memory. ``docs``: instruction documents (index -1 of a frame
    maps to the empty instruction); ``route``: (N,) route index for the validation split."""

    bev: np.ndarray           # (N, 7, 128, 16) uint8 bit-packed
    speed: np.ndarray         # (N,) m/s
    stopped_for: np.ndarray   # (N,) s
    waypoints: np.ndarray     # (N, K, 2) m
    target_speed: np.ndarray  # (N,) m/s
    doc: np.ndarray           # (N,) index into docs
    route: np.ndarray         # (N,) index into routes
    docs: list[dict]
    routes: list[str]


_EMPTY_DOC = {"text": "", "type": "none", "intent": "follow", "distance": None, "slots": {}}


def load_dataset(data: Path | list[Path]) -> Dataset:
    """Read ``DATA/collect.json`` and its episodes (of one or several folders)."""
    folders = [Path(d) for d in (data if isinstance(data, list) else [data])]
    files = []
    for d in folders:
        manifest = d / "collect.json"
        if not manifest.is_file():
            raise InputError(d, "collect.json", "no collected data here",
                             "run icrsumo collect --out DIR first")
        files += [d / "episodes" / n for n in json.loads(manifest.read_text(encoding="utf-8"))["episodes"]]
    parts: dict[str, list] = {k: [] for k in ("bev", "speed", "stopped_for", "waypoints", "target_speed",
                                              "doc", "route")}
    docs, doc_index, routes = [dict(_EMPTY_DOC)], {"": 0}, []
    for path in files:
        route = path.name.rsplit("__p", 1)[0]
        if route not in routes:
            routes.append(route)
        with np.load(path) as z:
            local = []
            for d in json.loads(str(z["instructions"])):
                key = json.dumps([d["text"], d["type"], d["intent"], d["distance"], d["slots"]])
                if key not in doc_index:
                    doc_index[key] = len(docs)
                    docs.append(d)
                local.append(doc_index[key])
            instr = z["instruction"].astype(np.int64)
            parts["doc"].append(np.where(instr >= 0, np.asarray(local + [0])[instr], 0))
            for k in ("bev", "speed", "stopped_for", "waypoints", "target_speed"):
                parts[k].append(z[k])
            parts["route"].append(np.full(len(instr), routes.index(route), dtype=np.int64))
    cat = {k: np.concatenate(v) for k, v in parts.items()}
    return Dataset(docs=docs, routes=routes, **cat)


def split(ds: Dataset, val_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Frame indices (train, validation); validation holds whole routes (at least one when
    ``val_fraction`` > 0 and there are two or more)."""
    h = np.array([zlib.crc32(f"{seed}:{r}".encode()) % 10_000 for r in ds.routes])
    held = h < val_fraction * 10_000
    if val_fraction > 0 and not held.any() and len(h) > 1:
        held[int(np.argmin(h))] = True   # at least one route held out
    is_val = held[ds.route]
    return np.flatnonzero(~is_val), np.flatnonzero(is_val)


def text_pool(ds: Dataset, cfg: TrainConfig, rng: np.random.Generator) -> list[list[str]]:
    """Per instruction document the texts trained on: its own text, or with augmentation
    ``variants`` texts drawn by :func:`icrsumo.learn.augment.augment` (training bank only)."""
    if not cfg.augment_instructions:
        return [[d["text"]] for d in ds.docs]
    return [[d["text"]] if d["type"] == "none" else
            [augment(d, rng, cfg.p_paraphrase, cfg.p_noise) for _ in range(cfg.variants)]
            for d in ds.docs]


def _intent_ids(ds: Dataset) -> np.ndarray:
    from .nets import INTENTS

    return np.array([INTENTS.index(d["intent"]) if d["intent"] in INTENTS else 0 for d in ds.docs])


# --------------------------------------------------------------------------- loop
def train(cfg: TrainConfig, data: Path | list[Path], out: Path, quiet: bool = False) -> dict:
    """Train (or resume) into ``out``; returns the final validation metrics."""
    import torch

    from . import nets

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cfg_doc = asdict(cfg)
    last = out / "last.pt"
    state = None
    if last.is_file():
        state = nets.load(last)
        if state.get("train_config") != cfg_doc:
            raise InputError(last, "train_config", "was written with a different config",
                             "use another --out folder, or the same config")
    rng = np.random.default_rng([cfg.seed, 1])
    t0 = time.perf_counter()
    ds = load_dataset(data)
    tr_idx, va_idx = split(ds, cfg.val_fraction, cfg.seed)
    pool = text_pool(ds, cfg, np.random.default_rng([cfg.seed, 2]))
    text_len = cfg.text_len or _DEFAULT_TEXT_LEN[cfg.encoder]
    vocab = tuple(build_vocab(t for texts in pool for t in texts)) if cfg.encoder == "token" else ()
    mcfg = nets.ModelConfig(encoder=cfg.encoder, text_len=text_len, buckets=cfg.buckets, vocab=vocab,
                            width=cfg.width, hidden=cfg.hidden)
    enc = mcfg.text_encoder()
    n_var = max(len(p) for p in pool)
    ids = np.zeros((len(pool), n_var, text_len), dtype=np.int64)
    n_texts = np.array([len(p) for p in pool])
    for i, texts in enumerate(pool):
        ids[i, : len(texts)] = enc.encode_many(texts)
    device = nets.pick_device(cfg.device)
    trainer = nets.Trainer(mcfg, cfg.seed, cfg.lr, cfg.weight_decay, cfg.steps, device)
    log_path = out / "train_log.jsonl"
    if state is not None:
        trainer.load_state(state)
        rng.bit_generator.state = state["rng"]
        if log_path.is_file():  # drop lines past the checkpoint: they are about to be redone
            kept = [ln for ln in log_path.read_text(encoding="utf-8").splitlines()
                    if ln and json.loads(ln)["step"] <= trainer.step]
            write_atomic(log_path, "".join(ln + "\n" for ln in kept))
    elif log_path.is_file():
        log_path.unlink()
    # the whole dataset on the device once
    dev = {k: torch.from_numpy(np.ascontiguousarray(getattr(ds, k))).to(device)
           for k in ("bev", "speed", "stopped_for", "waypoints", "target_speed", "doc")}
    dev["ids"] = torch.from_numpy(ids).to(device)
    dev["n_texts"] = torch.from_numpy(n_texts).to(device)
    dev["intent"] = torch.from_numpy(_intent_ids(ds)).to(device)

    def batch(idx: np.ndarray, variant: np.ndarray | None) -> dict:
        i = torch.from_numpy(idx).to(device)
        doc = dev["doc"][i]
        v = torch.zeros_like(doc) if variant is None else (
            torch.from_numpy(variant).to(device) % dev["n_texts"][doc])
        return {"bev": nets.unpack_bev(dev["bev"][i]), "speed": dev["speed"][i],
                "stopped_for": dev["stopped_for"][i], "waypoints": dev["waypoints"][i],
                "target_speed": dev["target_speed"][i], "ids": dev["ids"][doc, v],
                "intent": dev["intent"][doc]}

    val_rng = np.random.default_rng([cfg.seed, 3])
    val_idx = (np.sort(val_rng.choice(va_idx, size=min(len(va_idx), 4096), replace=False))
               if len(va_idx) else va_idx)
    val_var = val_rng.integers(0, 1 << 30, size=len(val_idx))
    if not quiet:
        print(f"icrsumo train: {len(tr_idx)} training / {len(va_idx)} validation frames, {len(ds.docs)} "
              f"instructions, {nets.parameter_count(trainer.model)} parameters on {device}, "
              f"from step {trainer.step}", file=sys.stderr)
    sums: dict[str, float] = {}
    n_sum = 0
    metrics: dict = {}
    while trainer.step < cfg.steps:
        idx = tr_idx[rng.integers(0, len(tr_idx), size=cfg.batch)]
        var = rng.integers(0, 1 << 30, size=cfg.batch)
        for k, v in trainer.train_step(batch(idx, var)).items():
            sums[k] = sums.get(k, 0.0) + v
        n_sum += 1
        step = trainer.step
        if step % cfg.eval_every == 0 or step == cfg.steps:
            metrics = {"step": step, "lr": trainer.sched.get_last_lr()[0],
                       "train": {k: round(v / n_sum, 5) for k, v in sums.items()},
                       "elapsed_s": round(time.perf_counter() - t0, 1)}
            if len(val_idx):
                res: dict[str, float] = {}
                for a in range(0, len(val_idx), 1024):
                    r = trainer.evaluate(batch(val_idx[a:a + 1024], val_var[a:a + 1024]))
                    w = len(val_idx[a:a + 1024]) / len(val_idx)
                    for k, v in r.items():
                        res[k] = res.get(k, 0.0) + v * w
                metrics["val"] = {k: round(v, 5) for k, v in res.items()}
            with open(log_path, "a", encoding="utf-8") as f:
                f.write(json.dumps(metrics) + "\n")
            if not quiet:
                print(f"icrsumo train: {json.dumps(metrics)}", file=sys.stderr)
            sums, n_sum = {}, 0
        if step % cfg.checkpoint_every == 0 or step == cfg.steps:
            nets.save(trainer.state({"train_config": cfg_doc, "rng": rng.bit_generator.state}), last)
    folders = data if isinstance(data, list) else [data]
    meta = {"data": [Path(d).name for d in folders], "frames": int(len(tr_idx)), "steps": trainer.step,
            "seed": cfg.seed, "augment_instructions": cfg.augment_instructions, "final": metrics}
    nets.export(trainer, out / "model.pt", meta)
    write_atomic(out / "train_summary.json", dumps_json({"format": TRAIN_FORMAT, "config": cfg_doc, **meta}))
    return metrics
