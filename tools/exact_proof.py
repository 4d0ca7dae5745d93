"""The exactness proof of the shipped learned agents on this machine's CPU.

    python tools/exact_proof.py --scenarios OUT/scenarios [--frames 10000] [--passes 3]
                                [--workers 2] [--json F]

Records ``--frames`` observations by driving the converted scenarios of an evaluation folder
(``OUT/scenarios``; clean and perturbed passes of the route-oracle), then for every shipped exact
checkpoint compares the fast path (1 and 2 BLAS threads, batches of 1 and 32) with the int64
reference on every frame (:mod:`icrsumo.learn.exact.proof`), one checkpoint per worker process.
Prints one line per checkpoint and the CPU's name; ``--json`` writes the results.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from cpu import cpu_name  # noqa: E402,F401  (benchmark scripts import it from here)

from icrsumo.learn.agent import CHECKPOINTS  # noqa: E402
from icrsumo.learn.exact.proof import prove, record  # noqa: E402
from icrsumo.world.scenario import find_scenarios  # noqa: E402

_FRAMES = None


def _init(frames) -> None:
    global _FRAMES
    _FRAMES = frames


def _prove(path: str) -> dict:
    return asdict(prove(path, _FRAMES))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", required=True, type=Path, help="OUT/scenarios of an evaluation folder")
    ap.add_argument("--frames", type=int, default=10000)
    ap.add_argument("--passes", type=int, default=3, help="drives per route (0 clean, others perturbed)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    frames = record(find_scenarios(args.scenarios), args.frames, passes=args.passes)
    t_rec = time.perf_counter() - t0
    print(f"{len(frames)} frames recorded in {t_rec:.0f} s; CPU: {cpu_name()}", flush=True)
    paths = [str(p) for p in sorted(CHECKPOINTS.glob("*.npz"))]
    with ProcessPoolExecutor(args.workers, initializer=_init, initargs=(frames,)) as pool:
        results = list(pool.map(_prove, paths))
    for r in results:
        verdict = ("bitwise equal" if r["mismatches"] == 0
                   else f"{r['mismatches']} frames differ ({r['first']})")
        print(f"{r['checkpoint']}: {r['frames']} frames x {len(r['variants'])} variants: {verdict} "
              f"({r['seconds']:.0f} s)")
    if args.json:
        args.json.write_text(json.dumps({"cpu": cpu_name(), "python": sys.version.split()[0],
                                         "frames": len(frames), "results": results}, indent=1))
    return 0 if all(r["mismatches"] == 0 for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
