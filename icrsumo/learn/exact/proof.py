"""The proof that an exact checkpoint's fast path is CPU-independent: its outputs on recorded
observations equal the int64 reference's bit for bit, with 1 and 2 BLAS threads and batches of
1 and 32 (``tools/exact_proof.py`` runs it on 10,000 frames per shipped checkpoint; the tests
and ``icrsumo check-agent`` on fewer).

Observations are recorded by driving converted scenarios with the route-oracle expert, clean and
perturbed passes (:func:`icrsumo.learn.collect.collect_episode`): the BEV rasters, speeds, stop
times and instruction texts a learned agent meets.
"""

from __future__ import annotations

import io
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .checkpoint import ExactCheckpoint, load
from .model import ExactPolicy, limit_blas_threads
from .reference import int64_engine

#: (BLAS threads, batch size) of the fast path compared with the reference
VARIANTS = ((1, 1), (1, 32), (2, 1), (2, 32))


@dataclass(frozen=True)
class Frames:
    """Recorded observations: ``bev`` (N, 7, H, W/8) bit-packed, ``texts`` (N,), ``speed``
    (N,) m/s and ``stopped`` (N,) s."""

    bev: np.ndarray
    texts: tuple[str, ...]
    speed: np.ndarray
    stopped: np.ndarray

    def __len__(self) -> int:
        return len(self.texts)

    def batch(self, idx: np.ndarray) -> tuple[np.ndarray, list[str], np.ndarray, np.ndarray]:
        bev = np.unpackbits(self.bev[idx], axis=-1) * np.uint8(255)
        return bev, [self.texts[i] for i in idx], self.speed[idx], self.stopped[idx]


@dataclass(frozen=True)
class ProofResult:
    """One checkpoint's comparison: ``frames`` compared in each of ``variants`` (threads,
    batch); ``mismatches`` frames whose outputs differed from the reference anywhere
    (``first``: the first, described); ``seconds`` wall time."""

    checkpoint: str
    frames: int
    variants: tuple[tuple[int, int], ...]
    mismatches: int
    first: str
    seconds: float

    @property
    def exact(self) -> bool:
        return self.mismatches == 0 and self.frames > 0


def record(scenarios: list[Path], frames: int, passes: int = 2, every: int = 1, seed: int = 0) -> Frames:
    """At least ``frames`` observations (or all there are) from driving ``scenarios`` in turn
    (pass 0 clean, the others perturbed), every ``every``-th agent step."""
    from ..collect import CollectOptions, collect_episode

    opts = CollectOptions(every=every, seed=seed)
    bevs, texts, speed, stopped, n = [], [], [], [], 0
    for k in range(passes):
        for sc in scenarios:
            raw, _ = collect_episode(str(sc), k, opts)
            with np.load(io.BytesIO(raw), allow_pickle=False) as z:
                docs = json.loads(str(z["instructions"]))
                bevs.append(z["bev"])
                texts += [docs[i]["text"] if i >= 0 else "" for i in z["instruction"]]
                speed.append(z["speed"])
                stopped.append(z["stopped_for"])
                n += len(z["speed"])
            if n >= frames:
                break
        if n >= frames:
            break
    keep = min(n, frames)
    f32 = np.float32
    return Frames(np.concatenate(bevs)[:keep], tuple(texts[:keep]), np.concatenate(speed)[:keep].astype(f32),
                  np.concatenate(stopped)[:keep].astype(f32))


def _run(policy: ExactPolicy, frames: Frames, batch: int) -> dict[str, np.ndarray]:
    n = len(frames)
    outs = [policy(*frames.batch(np.arange(i, min(i + batch, n)))) for i in range(0, n, batch)]
    return {k: np.concatenate([o[k] for o in outs]) for k in outs[0]}


def prove(checkpoint, frames: Frames, variants=VARIANTS) -> ProofResult:
    """Compare the fast path of ``checkpoint`` (a path or an :class:`ExactCheckpoint`) with the
    int64 reference on every frame."""
    t0 = time.perf_counter()
    ck = checkpoint if isinstance(checkpoint, ExactCheckpoint) else load(checkpoint)
    want = _run(ExactPolicy(ck, engine=int64_engine, threads=None), frames, 64)
    bad = np.zeros(len(frames), bool)
    first = ""
    for threads, batch in variants:
        limit_blas_threads(threads)
        got = _run(ExactPolicy(ck, threads=None), frames, batch)
        for key, ref in want.items():
            same = got[key] == ref
            diff = ~same.reshape(len(frames), -1).all(axis=1) | (got[key].dtype != ref.dtype)
            if diff.any() and not first:
                i = int(np.flatnonzero(diff)[0])
                first = f"frame {i}, output {key}, {threads} thread(s), batch {batch}"
            bad |= diff
    limit_blas_threads(1)
    name = Path(checkpoint).name if isinstance(checkpoint, (str, Path)) else "checkpoint"
    return ProofResult(name, len(frames), tuple(variants), int(bad.sum()), first,
                       time.perf_counter() - t0)
