"""How fast a smaller learned agent would act: the exact graph's ``act`` time at other widths.

    python tools/exact_width.py [--agent bev-ngram-aug] [--widths 8 16 24 32] [--calls 2000]
    python tools/exact_width.py --recorded COLLECT_FOLDER [--calls 2000]

Times one exact forward pass (batch 1, one BLAS thread: what a worker runs per decision) of the
shipped checkpoint ``--agent`` and of networks of the same layout at each ``--width`` (the CNN's
base channels; the shipped agents have 32) and ``--hidden`` MLP width, filled with random int8
weights of the shipped checkpoint's scale (speed does not depend on the weights' values). BEV frames
and texts come from a seeded generator: random pixels leave no 4x4 patch empty, so every patch is
multiplied (the graph's worst case: real BEVs skip the products of their empty patches), and no
call reuses the one before (``ExactPolicy(reuse=False)``). Prints the median ms per call of
each, and its ratio to the shipped checkpoint's measured in the same run, with the CPU's name: the
size a retrained network must have to reach a target (issue 48: ``act`` <= 0.3 ms).

With ``--recorded`` (a folder written by ``icrsumo collect``) it times the shipped checkpoint on
real BEVs instead: the first ``--calls`` frames of the collected drives in their recorded order,
each call afresh (``reuse=False``: only the empty patches skipped) and starting from the call
before (what an episode runs), and prints the share of empty patches.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from cpu import cpu_name  # noqa: E402
from policy_latency import median_ms  # noqa: E402

from icrsumo.learn.agent import CHECKPOINTS  # noqa: E402
from icrsumo.learn.exact.checkpoint import ExactCheckpoint, layout, load  # noqa: E402
from icrsumo.learn.exact.graph import drawn  # noqa: E402
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


def recorded(folder: Path, limit: int) -> tuple[list[np.ndarray], list[str], np.ndarray, np.ndarray]:
    """The first ``limit`` frames of an ``icrsumo collect`` folder's drives, in recorded order:
    BEVs (7, H, W) uint8, the instruction texts, speeds and stop times."""
    from icrsumo.core.errors import InputError
    from icrsumo.learn.collect import read_episode

    frames: list[np.ndarray] = []
    texts: list[str] = []
    speed: list[float] = []
    stopped: list[float] = []
    for path in sorted(Path(folder).glob("episodes/*.npz")):
        arr, docs = read_episode(path, ("bev", "speed", "instruction", "stopped_for"))
        n = min(len(arr["bev"]), limit - len(frames))
        frames += list(np.unpackbits(arr["bev"][:n], axis=-1) * np.uint8(255))
        texts += [docs[i]["text"] if i >= 0 else "" for i in arr["instruction"][:n]]
        speed += arr["speed"][:n].tolist()
        stopped += arr["stopped_for"][:n].tolist()
        if len(frames) >= limit:
            break
    if not frames:
        raise InputError(folder, "", "no collected episodes found",
                         "give a folder written by icrsumo collect")
    return frames, texts, np.array(speed, np.float32), np.array(stopped, np.float32)


def in_order_ms(policy: ExactPolicy, frames: list[np.ndarray], texts: list[str], speed: np.ndarray,
                stopped: np.ndarray, repeats: int = 5) -> float:
    """Median over ``repeats`` passes of the mean ms of one batch-1 call, the frames in order."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for i, f in enumerate(frames):
            policy(f[None], [texts[i]], speed[i:i + 1], stopped[i:i + 1])
        times.append((time.perf_counter() - t0) * 1e3 / len(frames))
    return float(np.median(times))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agent", default="bev-ngram-aug")
    ap.add_argument("--widths", nargs="+", type=int, default=[8, 16, 24, 32])
    ap.add_argument("--hidden", type=int, default=None, help="MLP width of the smaller networks "
                    "(default: the shipped one's)")
    ap.add_argument("--calls", type=int, default=2000)
    ap.add_argument("--recorded", type=Path, default=None, help="an icrsumo collect folder: time the "
                    "shipped checkpoint on its frames in recorded order")
    a = ap.parse_args(argv)
    shipped = load(CHECKPOINTS / f"{a.agent}.npz")
    if a.recorded is not None:
        from icrsumo.core.errors import InputError

        try:
            frames, texts, speed, stopped = recorded(a.recorded, a.calls)
        except InputError as err:
            print(f"exact_width: {err}", file=sys.stderr)
            return 2
        empty = 1.0 - float(np.mean([drawn(f[None]).mean() for f in frames]))
        fresh = in_order_ms(ExactPolicy(shipped, reuse=False), frames, texts, speed, stopped)
        before = in_order_ms(ExactPolicy(shipped), frames, texts, speed, stopped)
        print(f"{a.agent} on {len(frames)} recorded frames in order ({100 * empty:.1f} % of the BEV "
              f"patches empty): {fresh:.3f} ms per act afresh, {before:.3f} ms starting from the call "
              f"before ({before / fresh:.2f}x)")
        print(f"median of 5 passes, batch 1, one BLAS thread; {cpu_name()}")
        return 0
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
