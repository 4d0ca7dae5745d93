"""``icrsumo train``: behaviour cloning of the expert's plan from ``icrsumo collect`` data.

Config: a TOML file of :class:`TrainConfig` keys (unknown keys are refused). Seeded: the
initial weights, the validation split (by route), the batch order and the instruction
augmentation all follow ``seed`` through ``numpy.random.Generator`` objects (and a forked torch
RNG for the initial weights). Progress goes to stderr (unless ``quiet``): a line per stage
before training, then a bar of the steps with the mean training loss. Every ``eval_every``
steps one JSON line with the mean training losses since the last line and the validation
metrics goes to ``OUT/train_log.jsonl`` (and to stderr); every ``checkpoint_every`` steps the
whole state goes to ``OUT/last.pt``, from which a rerun with the same config resumes. At the
end the inference checkpoint ``OUT/model.pt`` is exported (float32, loaded with
``torch.load(..., weights_only=True)``).

Runs on CPU (slowly) or on a GPU (``device = "auto"`` picks CUDA when present); the whole
dataset (bit-packed rasters) is moved to the device once, so a GPU is never starved.

Bad input is an :class:`icrsumo.core.errors.InputError` naming the file, the place and the fix: the
config (encoding, TOML syntax, unknown keys, every key's type from :class:`TrainConfig`'s field
types, ranges, a device that is unknown or not available), the data folders (manifest, episode
files) and a resume checkpoint ``OUT/last.pt``. All of it is checked before OUT is made or
touched, so a refused run writes nothing.
"""

from __future__ import annotations

import difflib
import functools
import json
import math
import re
import sys
import time
import tomllib
import zlib
from collections.abc import Callable
from dataclasses import Field, asdict, dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from icrsumo.core.errors import Field as Named
from icrsumo.core.errors import InputError, expect
from icrsumo.core.fsio import dumps_json, read_json_doc, read_text, write_atomic
from icrsumo.core.procs import spawn_context

from .augment import augment
from .config import ModelConfig
from .text import ENCODERS, VECTOR_ENCODERS, build_vocab

if TYPE_CHECKING:
    import torch

    from .nets import Trainer

TRAIN_FORMAT = "icrsumo-train/1"
_DEFAULT_TEXT_LEN = {"token": 32, "ngram": 192, "minilm": 384, "minilm-tuned": 64 * 384}


#: upper bounds of the integer sizes of a training config (a value past them cannot run here)
LIMITS = {"steps": 10**8, "batch": 65_536, "eval_every": 10**8, "checkpoint_every": 10**8, "width": 4096,
          "hidden": 4096, "variants": 1024}


@dataclass(frozen=True)
class TrainConfig:
    """Training options (TOML keys). Sizes in frames; ``lr`` peak of a one-cycle schedule
    (``lr_tuned`` that of the pretrained layer the ``minilm-tuned`` encoder fine-tunes);
    ``val_fraction`` of routes held out; ``variants`` augmented texts drawn per instruction."""

    encoder: str = "ngram"
    augment_instructions: bool = False
    seed: int = 0
    steps: int = 20000
    batch: int = 256
    lr: float = 1e-3
    lr_tuned: float = 1e-4
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

    def check(self, where: str | Path = "train config", sources: dict[str, Named] | None = None,
              places: dict[str, str] | None = None) -> None:
        """InputErrors for a value of the wrong type (from the field types), out of range, or a
        device that is unknown or not available here. ``where`` names the config (its file),
        ``sources`` the field a key was given by instead (``{"steps": Named("steps")}``) and
        ``places`` where in the file each key is (``{"lr": "line 4 (lr)"}``)."""
        sources, places = sources or {}, places or {}

        def loc(name: str) -> tuple[str | Path | Named, str]:
            if name in sources:
                return sources[name], ""
            return str(where), places.get(name, name)

        def fail(name: str, problem: str, fix: str) -> None:
            raise InputError(*loc(name), problem, fix)

        for f in fields(self):
            value = getattr(self, f.name)
            kind = _kind(f)
            if kind is float and isinstance(value, int) and not isinstance(value, bool):
                continue
            expect(value, kind, *loc(f.name), f.name, f"write e.g. {f.name} = {_toml(f.default)}")
            if kind is float and not math.isfinite(value):
                fail(f.name, f"{f.name} must be a finite number, not {value}",
                     f"write e.g. {f.name} = {f.default}")
        if self.encoder not in ENCODERS:
            fail("encoder", f"unknown encoder {self.encoder!r}", f"use one of {', '.join(ENCODERS)}")
        for name, most in LIMITS.items():
            if not 1 <= getattr(self, name) <= most:
                fail(name, f"{name} must be 1 to {most:,}, not {getattr(self, name)}",
                     f"give 1 to {most:,}")
        if not 2 <= self.buckets <= 1 << 24:
            fail("buckets", f"buckets must be 2 to {1 << 24:,}, not {self.buckets}", "give e.g. 8192")
        if not 0 <= self.text_len <= 4096:
            fail("text_len", f"text_len must be 0 to 4096, not {self.text_len}",
                 "give 0 (the encoder's default) or a positive length")
        size = _DEFAULT_TEXT_LEN.get(self.encoder, 0)
        if self.encoder in VECTOR_ENCODERS and self.text_len not in (0, size):
            fail("text_len", f"the {self.encoder} encoder's vector has {size} values, not {self.text_len}",
                 "leave text_len out (0)")
        if not 0 <= self.seed < 2**63:
            fail("seed", f"seed {self.seed} out of range", "use 0 to 2**63 - 1")
        for name, example in (("lr", 0.001), ("lr_tuned", 0.0001)):
            if not getattr(self, name) > 0:
                fail(name, f"{name} must be positive, not {getattr(self, name)}",
                     f"give e.g. {name} = {example}")
        if not self.weight_decay >= 0:
            fail("weight_decay", f"weight_decay must not be negative, not {self.weight_decay}",
                 "give 0 or e.g. 0.0001")
        if not 0.0 <= self.val_fraction < 0.5:
            fail("val_fraction", f"val_fraction {self.val_fraction} out of range", "use 0 to 0.5")
        for name in ("p_paraphrase", "p_noise"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                fail(name, f"{name} {getattr(self, name)} is not a probability", "use 0 to 1")
        from .nets import pick_device

        pick_device(self.device, *loc("device"))


_KINDS = {"str": str, "bool": bool, "int": int, "float": float}


def _kind(f: Field) -> type:
    """The type of a config field (annotations are strings here: ``from __future__``)."""
    return f.type if isinstance(f.type, type) else _KINDS[f.type]


def _toml(value: object) -> str:
    """``value`` as a TOML literal (for the fixes in messages)."""
    return ("true" if value else "false") if isinstance(value, bool) else json.dumps(value)


def _toml_error(path: Path, err: tomllib.TOMLDecodeError) -> InputError:
    m = re.fullmatch(r"(.*) \(at (line \d+, column \d+|end of document)\)", str(err), re.S)
    msg, place = (m.group(1), m.group(2)) if m else (str(err), "")
    return InputError(path, place, f"not valid TOML ({msg})", "fix the TOML syntax there")


def read_config(path: Path, **overrides: object) -> TrainConfig:
    """Read a TOML config; ``overrides`` (non-None: the command line's ``--steps``,
    ``--device``, ...) replace its values. Every problem (file, encoding, syntax, unknown key,
    type, range, device) is an InputError naming the file and the key, or the option."""
    path = Path(path)
    text = read_text(path, "training config", "give the path of a TOML training config (see "
                     "icrsumo/learn/checkpoints/*.toml)")
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise _toml_error(path, err) from None
    known = {f.name: f for f in fields(TrainConfig)}
    places = {key: _key_line(text, key) for key in raw}
    for key in raw:
        if key not in known:
            close = difflib.get_close_matches(key, known, n=1)
            raise InputError(path, places[key], f"unknown key {key!r}",
                             (f"did you mean {close[0]}? " if close else "") + f"keys: {', '.join(known)}")
    sources = {}
    for key, value in overrides.items():
        if value is not None:
            raw[key] = value
            sources[key] = Named(key)
    for key, value in raw.items():  # integers given for float keys (lr = 1) are floats
        if _kind(known[key]) is float and isinstance(value, int) and not isinstance(value, bool):
            raw[key] = float(value)
    cfg = TrainConfig(**raw)
    cfg.check(path, sources, places)
    return cfg


def _key_line(text: str, key: str) -> str:
    """``line N (key)`` of the first line that sets top-level ``key`` (or opens table
    ``[key]``), else ``key``."""
    name = rf"""(?:{re.escape(key)}|"{re.escape(key)}"|'{re.escape(key)}')"""
    pat = re.compile(rf"\s*(?:{name}\s*[=.]|\[\s*{name}\s*[\].])")
    for n, line in enumerate(text.splitlines(), 1):
        if pat.match(line):
            return f"line {n} ({key})"
    return key


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


def _episode_files(d: Path) -> list[Path]:
    """The episode files that ``d/collect.json`` lists; InputErrors for a missing folder or
    manifest, a manifest that is not JSON or not a collect manifest, and an empty list."""
    from .collect import COLLECT_FORMAT

    fix = f"run icrsumo collect --out {d} first"
    if not d.exists():
        raise InputError(d, "", "data folder not found", f"check the {Named('data')} path, or {fix}")
    if not d.is_dir():
        raise InputError(d, "", "is not a folder", "give the folder written by icrsumo collect --out DIR")
    manifest = d / "collect.json"
    if not manifest.exists():
        raise InputError(d, "collect.json", "no collected data here (not an icrsumo collect folder)", fix)
    doc = read_json_doc(manifest, COLLECT_FORMAT, "collect manifest",
                        f"rerun icrsumo collect --out {d} with the same options")
    names = expect(doc.get("episodes"), list, manifest, "episodes", "the episode list",
                   f"rerun icrsumo collect --out {d} with the same options")
    if not names:
        raise InputError(manifest, "episodes", "lists no episodes", "collect from more routes or passes")
    for i, n in enumerate(names):
        expect(n, str, manifest, f"episodes[{i}]", "an episode file name", fix)
        if Path(n).name != n or not n.endswith(".npz"):
            raise InputError(manifest, f"episodes[{i}]", f"{n!r} is not an episode file name (NAME.npz)",
                             f"rerun icrsumo collect --out {d} with the same options")
    return [d / "episodes" / n for n in names]


def load_dataset(data: Path | list[Path]) -> Dataset:
    """Read ``DATA/collect.json`` and its episodes (of one or several folders). A missing or
    damaged folder, manifest or episode file, and data without frames, are InputErrors naming
    the file."""
    from .collect import read_episode

    folders = [Path(d) for d in (data if isinstance(data, list) else [data])]
    files = [f for d in folders for f in _episode_files(d)]
    parts: dict[str, list] = {k: [] for k in ("bev", "speed", "stopped_for", "waypoints", "target_speed",
                                              "doc", "route")}
    docs, doc_index, routes = [dict(_EMPTY_DOC)], {"": 0}, []
    for path in files:
        route = path.name.rsplit("__p", 1)[0]
        if route not in routes:
            routes.append(route)
        z, ep_docs = read_episode(path, ("instruction", "bev", "speed", "stopped_for", "waypoints",
                                         "target_speed"))
        local = []
        for d in ep_docs:
            key = json.dumps([d["text"], d["type"], d["intent"], d.get("distance"), d["slots"]])
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
    if not len(cat["speed"]):
        raise InputError(folders[0], "", "the collected episodes hold no frames",
                         "collect from more routes or passes")
    return Dataset(docs=docs, routes=routes, **cat)


def _log_lines(path: Path, step: int) -> list[str]:
    """The lines of an earlier run's ``train_log.jsonl`` up to ``step`` (those past it are about
    to be redone); a line that is not a JSON object with a step is an InputError."""
    kept = []
    for n, ln in enumerate(read_text(path, "training log").splitlines(), 1):
        if not ln:
            continue
        try:
            doc = json.loads(ln)
            s = doc["step"]
        except (json.JSONDecodeError, TypeError, KeyError):
            raise InputError(path, f"line {n}", "not a JSON line with a step",
                             "delete the damaged line, or the whole log") from None
        if not isinstance(s, int) or isinstance(s, bool):
            raise InputError(path, f"line {n}", "its step is not an integer",
                             "delete the damaged line, or the whole log")
        if s <= step:
            kept.append(ln)
    return kept


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


def _encode_chunk(args: tuple) -> np.ndarray:
    enc, texts = args
    return enc.encode_many(texts)


def encode_texts(enc, texts: list[str], workers: int = 1) -> np.ndarray:
    """``enc.encode_many(texts)``, over ``workers`` processes for the pretrained encoder (whose
    per-text cost dominates); the same arrays whatever the worker count."""
    if workers <= 1 or enc.kind not in VECTOR_ENCODERS or len(texts) < 1000:
        return enc.encode_many(texts)

    size = -(-len(texts) // (workers * 4))
    chunks = [(enc, texts[i:i + size]) for i in range(0, len(texts), size)]
    with spawn_context().Pool(workers) as pool:
        return np.concatenate(pool.map(_encode_chunk, chunks))


def _intent_ids(ds: Dataset) -> np.ndarray:
    from .nets import INTENTS

    return np.array([INTENTS.index(d["intent"]) if d["intent"] in INTENTS else 0 for d in ds.docs])


# --------------------------------------------------------------------------- loop
def _say(text: str, quiet: bool) -> None:
    """One line of progress on stderr (none when ``quiet``)."""
    if not quiet:
        print(f"icrsumo train: {text}", file=sys.stderr, flush=True)


def step_bar(steps: int, done: int, quiet: bool):
    """The progress of training on stderr (a tqdm bar: steps done of ``steps``, steps per
    second, time left, the mean training loss since the last validation line); None when
    ``quiet``. On a terminal a live bar; otherwise (a log file) a line at most every 30 s."""
    if quiet:
        return None
    from tqdm import tqdm

    tty = bool(getattr(sys.stderr, "isatty", lambda: False)())
    return tqdm(total=steps, initial=done, desc="icrsumo train", unit="step", file=sys.stderr,
                dynamic_ncols=tty, ascii=not tty, leave=True, smoothing=0.1, miniters=1,
                mininterval=0.1 if tty else 30.0)


def _resume_state(cfg: TrainConfig, out: Path) -> dict | None:
    """The training state ``out/last.pt`` to resume from, checked against ``cfg`` (None: a fresh
    run); ``out`` is a folder or does not exist yet. Reads only: a refused run writes nothing."""
    from . import nets

    if out.exists() and not out.is_dir():
        raise InputError(out, "", "exists and is not a folder", "give a new folder, or an earlier run's")
    last = out / "last.pt"
    if not last.exists():
        return None
    fix = f"delete it to start over, or use another {Named('out')} folder"
    state = nets.load(last, "training checkpoint", fix)
    if state.get("format") != nets.STATE_FORMAT:
        raise InputError(last, "format", f"not an icrsumo training checkpoint (format "
                         f"{str(state.get('format'))[:40]!r})", fix)
    if state.get("train_config") != asdict(cfg):
        raise InputError(last, "train_config", "was written with a different config",
                         f"use another {Named('out')} folder, or the same config")
    return state


def _training_split(ds: Dataset, cfg: TrainConfig, data: Path | list[Path]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`split`'s training and validation frames; an InputError naming the first data
    folder when no route is left for training."""
    tr_idx, va_idx = split(ds, cfg.val_fraction, cfg.seed)
    if not len(tr_idx):
        folders = data if isinstance(data, list) else [data]
        raise InputError(folders[0], "", f"all {len(ds.routes)} routes of the data fall in the validation "
                         f"split (val_fraction {cfg.val_fraction})",
                         "collect more routes, or lower val_fraction in the config")
    return tr_idx, va_idx


def _instruction_ids(ds: Dataset, cfg: TrainConfig, encode_workers: int,
                     say: Callable[[str], None]) -> tuple[ModelConfig, np.ndarray, np.ndarray]:
    """The model config and the encoded training texts: ids ``(instructions, variants,
    text_len)`` (each distinct text encoded once) and how many texts each instruction has."""
    pool = text_pool(ds, cfg, np.random.default_rng([cfg.seed, 2]))
    text_len = cfg.text_len or _DEFAULT_TEXT_LEN[cfg.encoder]
    vocab = tuple(build_vocab(t for texts in pool for t in texts)) if cfg.encoder == "token" else ()
    mcfg = ModelConfig(encoder=cfg.encoder, text_len=text_len, buckets=cfg.buckets, vocab=vocab,
                       width=cfg.width, hidden=cfg.hidden)
    enc = mcfg.text_encoder()
    n_var = max(len(p) for p in pool)
    ids = np.zeros((len(pool), n_var, text_len), dtype=enc.dtype)
    n_texts = np.array([len(p) for p in pool])
    distinct = list(dict.fromkeys(t for texts in pool for t in texts))  # each text encoded once
    row = {t: i for i, t in enumerate(distinct)}
    say(f"read {len(ds.routes)} routes; encoding {len(distinct)} instruction texts "
        f"({cfg.encoder} encoder) ...")
    codes = encode_texts(enc, distinct, encode_workers)
    for i, texts in enumerate(pool):
        ids[i, : len(texts)] = codes[[row[t] for t in texts]]
    return mcfg, ids, n_texts


def _resume(trainer: Trainer, state: dict | None, rng: np.random.Generator, out: Path) -> None:
    """``trainer`` and ``rng`` resumed from ``state`` (None: a fresh run), then ``out`` made and
    its ``train_log.jsonl`` cut back to the resumed step (removed for a fresh run)."""
    last, log_path = out / "last.pt", out / "train_log.jsonl"
    kept: list[str] = []
    if state is not None:
        trainer.load_state(state, last)
        try:
            rng.bit_generator.state = state.get("rng")
        except (TypeError, ValueError, KeyError):
            raise InputError(last, "rng", "not a random generator state", "delete it to start over, "
                             f"or use another {Named('out')} folder") from None
        if log_path.exists():  # drop lines past the checkpoint: they are about to be redone
            kept = _log_lines(log_path, trainer.step)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(out, "", f"cannot make the output folder ({err.strerror or err})",
                         "give a folder in a writable place") from None
    if state is not None:
        if log_path.exists():
            write_atomic(log_path, "".join(ln + "\n" for ln in kept))
    elif log_path.is_file():
        log_path.unlink()


def _batcher(ds: Dataset, ids: np.ndarray, n_texts: np.ndarray, device: torch.device) -> Callable[..., dict]:
    """``batch(idx, variant)``: the frames ``idx`` as a training batch, each with the text
    ``variant`` (None: the first) of its instruction; the whole dataset is moved to ``device``
    once, here."""
    import torch

    from . import nets

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

    return batch


def _validation_frames(va_idx: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """At most 4096 of the validation frames (sorted) and each one's text variant."""
    val_rng = np.random.default_rng([seed, 3])
    val_idx = (np.sort(val_rng.choice(va_idx, size=min(len(va_idx), 4096), replace=False))
               if len(va_idx) else va_idx)
    return val_idx, val_rng.integers(0, 1 << 30, size=len(val_idx))


def _validate(trainer: Trainer, batch: Callable[..., dict], val_idx: np.ndarray, val_var: np.ndarray) -> dict:
    """The validation metrics over ``val_idx`` (in chunks of 1024 frames, weighted by size)."""
    res: dict[str, float] = {}
    for a in range(0, len(val_idx), 1024):
        r = trainer.evaluate(batch(val_idx[a:a + 1024], val_var[a:a + 1024]))
        w = len(val_idx[a:a + 1024]) / len(val_idx)
        for k, v in r.items():
            res[k] = res.get(k, 0.0) + v * w
    return {k: round(v, 5) for k, v in res.items()}


def _run_steps(cfg: TrainConfig, trainer: Trainer, batch: Callable[..., dict], tr_idx: np.ndarray,
               val: tuple[np.ndarray, np.ndarray], rng: np.random.Generator, out: Path, quiet: bool,
               t0: float) -> dict:
    """Train from ``trainer.step`` to ``cfg.steps``: a metrics line to ``out/train_log.jsonl``
    every ``eval_every`` steps and at the end, the state to ``out/last.pt`` every
    ``checkpoint_every`` steps and at the end; returns the last metrics line."""
    from . import nets

    cfg_doc = asdict(cfg)
    sums: dict[str, float] = {}
    n_sum = 0
    metrics: dict = {}
    bar = step_bar(cfg.steps, trainer.step, quiet)
    while trainer.step < cfg.steps:
        idx = tr_idx[rng.integers(0, len(tr_idx), size=cfg.batch)]
        var = rng.integers(0, 1 << 30, size=cfg.batch)
        for k, v in trainer.train_step(batch(idx, var)).items():
            sums[k] = sums.get(k, 0.0) + v
        n_sum += 1
        step = trainer.step
        if bar is not None:
            bar.set_postfix_str(f"loss {sums.get('total', 0.0) / n_sum:.4f}", refresh=False)
            bar.update(1)
        if step % cfg.eval_every == 0 or step == cfg.steps:
            metrics = {"step": step, "lr": trainer.sched.get_last_lr()[0],
                       "train": {k: round(v / n_sum, 5) for k, v in sums.items()},
                       "elapsed_s": round(time.perf_counter() - t0, 1)}
            if len(val[0]):
                metrics["val"] = _validate(trainer, batch, *val)
            with open(out / "train_log.jsonl", "a", encoding="utf-8") as f:
                f.write(json.dumps(metrics) + "\n")
            if bar is not None:
                bar.write(f"icrsumo train: {json.dumps(metrics)}", file=sys.stderr)
            sums, n_sum = {}, 0
        if step % cfg.checkpoint_every == 0 or step == cfg.steps:
            state = trainer.state({"train_config": cfg_doc, "rng": rng.bit_generator.state})
            nets.save(state, out / "last.pt")
    if bar is not None:
        bar.close()
    return metrics


def train(cfg: TrainConfig, data: Path | list[Path], out: Path, quiet: bool = False,
          encode_workers: int = 1) -> dict:
    """Train (or resume) into ``out``; returns the final validation metrics. ``encode_workers``:
    processes that compute the pretrained encoder's embeddings of the training texts (the same
    embeddings whatever their number)."""
    from . import nets

    # everything is checked before OUT is made or touched: a refused run writes nothing
    cfg.check()
    out = Path(out)
    state = _resume_state(cfg, out)
    rng = np.random.default_rng([cfg.seed, 1])
    t0 = time.perf_counter()
    say = functools.partial(_say, quiet=quiet)
    ds = load_dataset(data)  # (progress only once the data is known good: a refusal is one line)
    tr_idx, va_idx = _training_split(ds, cfg, data)
    mcfg, ids, n_texts = _instruction_ids(ds, cfg, encode_workers, say)
    device = nets.pick_device(cfg.device, "device")
    trainer = nets.Trainer(mcfg, cfg.seed, cfg.lr, cfg.weight_decay, cfg.steps, device, cfg.lr_tuned)
    _resume(trainer, state, rng, out)
    batch = _batcher(ds, ids, n_texts, device)
    val = _validation_frames(va_idx, cfg.seed)
    say(f"{len(tr_idx)} training / {len(va_idx)} validation frames, {len(ds.docs)} instructions, "
        f"{nets.parameter_count(trainer.model)} parameters on {device}, from step {trainer.step}")
    metrics = _run_steps(cfg, trainer, batch, tr_idx, val, rng, out, quiet, t0)
    folders = data if isinstance(data, list) else [data]
    meta = {"data": [Path(d).name for d in folders], "frames": int(len(tr_idx)), "steps": trainer.step,
            "seed": cfg.seed, "augment_instructions": cfg.augment_instructions, "final": metrics}
    nets.export(trainer, out / "model.pt", meta)
    summary = {"format": TRAIN_FORMAT, "config": asdict(cfg), **meta}
    write_atomic(out / "train_summary.json", dumps_json(summary))
    return metrics
