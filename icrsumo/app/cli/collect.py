"""``icrsumo collect``: expert driving data for training.
Its parser (``add``) and its handler (``run``)."""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from .options import add_traffic
from .registry import Commands


def add(sub: Commands) -> None:
    """Add the parser of ``icrsumo collect``."""
    c = sub.add_parser(
        "collect", help="expert driving data (BEV, speed, instruction, expert plan) for training",
        description="Drive the train split (or carla-train, carla-focus on CARLA's towns; never an "
        "evaluation suite) with the route-oracle as expert, with perturbed passes for recovery data; store "
        "bit-packed rasters and labels per episode (resumable).",
    )
    c.add_argument("--out", required=True, help="output folder")
    c.add_argument("--suite", default="train",
                   help="train (default), carla-train, carla-focus, a route XML or a convert-routes folder")
    c.add_argument("--passes", type=int, default=3, help="passes per route; pass 0 clean, others perturbed")
    c.add_argument("--seed", type=int, default=0, help="seed of phrasings and perturbations")
    c.add_argument("--every", type=int, default=2, help="store every n-th agent step (default 2: 5 Hz)")
    add_traffic(c)
    c.add_argument("--limit", type=int, default=0, help="only the first N routes (0: all)")
    c.add_argument("--driver", help="learned agent (name or checkpoint) that drives while the expert "
                   "labels (DAgger)")
    c.add_argument("--no-memory", dest="memory", action="store_false",
                   help="record the active instruction on every frame, not the text the learned "
                   "agents' instruction memory hands their network (data as before issue 47)")
    c.add_argument("--vary-leads", action="store_true",
                   help="each junction's instructions arrive at distances drawn per junction "
                   "(training data only) instead of the benchmark's fixed layout")
    c.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="worker processes (default: number of cores)")
    c.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``icrsumo collect``; its exit status."""
    from icrsumo.learn.collect import CollectOptions, collect

    t0 = time.perf_counter()
    opts = CollectOptions(suite=args.suite, passes=args.passes, seed=args.seed, every=args.every,
                          traffic=args.traffic, workers=args.workers, limit=args.limit,
                          driver=args.driver or "", memory=args.memory,
                          vary_leads=args.vary_leads)
    m = collect(opts, Path(args.out))
    print(f"{len(m['episodes'])} episodes, {m['frames']} frames in {time.perf_counter() - t0:.1f} s "
          f"-> {args.out}")
    return 0
