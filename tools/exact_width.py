"""How fast a smaller learned agent would act: the exact graph's ``act`` time at other widths.

    python tools/exact_width.py [--agent bev-ngram-aug] [--widths 8 16 24 32] [--calls 2000]

Times one exact forward pass (batch 1, one BLAS thread: what a worker runs per decision) of the
shipped checkpoint ``--agent`` and of networks of the same layout at each ``--width`` (the CNN's
base channels; the shipped agents have 32) and ``--hidden`` MLP width, filled with random int8
weights of the shipped checkpoint's scale (speed does not depend on the weights' values). BEV frames
and texts come from a seeded generator: random pixels leave no 4x4 patch empty, so every patch is
multiplied (the graph's worst case: real BEVs skip the products of their empty patches), and no
call reuses the one before (``ExactPolicy(reuse=False)``). Prints the median ms per call of
each, and its ratio to the shipped checkpoint's measured in the same run, with the CPU's name: the
size a retrained network must have to reach a target (issue 48: ``act`` <= 0.3 ms).
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from cpu import cpu_name  # noqa: E402
from policy_latency import median_ms  # noqa: E402

from icrsumo.learn.agent import CHECKPOINTS  # noqa: E402
from icrsumo.learn.exact.checkpoint import ExactCheckpoint, layout, load  # noqa: E402
from icrsumo.learn.exact.model import ExactPolicy  # noqa: E402


def random_checkpoint(shipped: ExactCheckpoint, width: int, hidden: int, seed: int = 0) -> ExactCheckpoint:
    """A checkpoint of ``shipped``'s layout at ``width`` / ``hidden``: the shipped arrays where the
    shape is unchanged (the language side), else random values in the shipped array's range."""
    cfg = dataclasses.replace(shipped.config, width=width, hidden=hidden)
    rng = np.random.default_rng(seed)
    arrays = {}
    for name, (shape, dtype) in layout(cfg).items():
        old = shipped.arrays[name]
        if old.shape == shape:
            arrays[name] = old
        elif dtype.kind == "i":
            top = max(int(np.abs(old).max()), 1)
            arrays[name] = rng.integers(-top, top + 1, size=shape).astype(dtype)
        else:
            arrays[name] = rng.uniform(float(old.min()), float(old.max()), size=shape).astype(dtype)
    return ExactCheckpoint(config=cfg, arrays=arrays, meta={"source": f"random width {width}"})


def act_ms(policy: ExactPolicy, frames: list[np.ndarray], texts: list[str], calls: int) -> float:
    """Median ms of one batch-1 call over ``calls`` calls cycling through ``frames`` and ``texts``."""
    speed, stopped, i = np.array([5.0], np.float32), np.array([0.0], np.float32), itertools.count()

    def one() -> None:
        n = next(i)
        policy(frames[n % len(frames)][None], [texts[n % len(texts)]], speed, stopped)
    return median_ms(one, calls)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agent", default="bev-ngram-aug")
    ap.add_argument("--widths", nargs="+", type=int, default=[8, 16, 24, 32])
    ap.add_argument("--hidden", type=int, default=None, help="MLP width of the smaller networks "
                    "(default: the shipped one's)")
    ap.add_argument("--calls", type=int, default=2000)
    a = ap.parse_args(argv)
    shipped = load(CHECKPOINTS / f"{a.agent}.npz")
    hidden = a.hidden or shipped.config.hidden
    rng = np.random.default_rng(2026)
    frames = [(rng.random((7, 128, 128)) < 0.15).astype(np.uint8) * 255 for _ in range(16)]
    texts = ["Turn left at the next intersection.", "Follow the road.", "Change to the right lane."]
    base = act_ms(ExactPolicy(shipped, reuse=False), frames, texts, a.calls)
    print(f"{a.agent} (shipped, width {shipped.config.width}, hidden {shipped.config.hidden}): "
          f"{base:.3f} ms per act")
    for w in a.widths:
        policy = ExactPolicy(random_checkpoint(shipped, w, hidden), reuse=False)
        ms = act_ms(policy, frames, texts, a.calls)
        print(f"width {w}, hidden {hidden}: {ms:.3f} ms per act ({ms / base:.2f}x the shipped)")
    print(f"median of {a.calls} calls each, batch 1, one BLAS thread; {cpu_name()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
