"""``icrsumo convert-routes``: leaderboard route XML to runnable SUMO scenarios.
Its parser (``add``) and its handler (``run``)."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from .options import add_traffic, names, suites
from .registry import Commands


def add(sub: Commands) -> None:
    """Add the parser of ``icrsumo convert-routes``."""
    p = sub.add_parser(
        "convert-routes", help="leaderboard route XML -> runnable SUMO scenarios",
        description=f"Convert a leaderboard-style route file (or a bundled suite: {suites()}) into "
        "SUMO scenarios with background traffic.",
    )
    p.add_argument("routes", help=f"route XML file, or the name of a bundled suite ({suites()})")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--net", type=Path, help="use this .net.xml for every route")
    p.add_argument("--xodr", type=Path, help="convert this OpenDRIVE file (cached) for every route")
    p.add_argument("--net-dir", type=Path,
                   help="folder with <town>.net.xml or <town>.xodr per route town")
    p.add_argument("--coords", choices=["sumo", "carla"], default=None,
                   help="waypoint frame: sumo (default) or CARLA's left-handed frame (a bundled "
                        "suite's own frame by default: carla for langauto-* and carla-*)")
    add_traffic(p)
    p.add_argument("--max-snap", type=float, default=10.0,
                   help="farthest a waypoint may lie from a drivable lane (m, default 10)")
    p.add_argument("--seed", type=int, default=0,
                   help="base seed; each route's seed derives from it and the route id")
    p.add_argument("--warmup", type=float, default=20.0,
                   help="seconds of background traffic before the ego departs (default 20)")
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="worker processes (default: number of cores)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``icrsumo convert-routes``; its exit status."""
    from icrsumo.core.resources import suite_coords
    from icrsumo.world.convert import ConvertOptions, convert_routes
    from icrsumo.world.routes import suite_file

    routes = suite_file(args.routes, "routes")
    opts = ConvertOptions(
        coords=args.coords or suite_coords(args.routes) or "sumo", traffic=args.traffic, net=args.net,
        xodr=args.xodr, net_dir=args.net_dir, max_snap=args.max_snap, seed=args.seed, warmup=args.warmup,
        workers=args.workers,
    )
    t0 = time.perf_counter()
    report = convert_routes(routes, Path(args.out), opts, refuse_empty=True)
    dt = time.perf_counter() - t0
    print(
        f"{len(report.converted)} converted, {len(report.reused)} reused, "
        f"{len(report.failures)} failed in {dt:.1f} s -> {args.out}",
        file=sys.stderr,
    )
    for err in report.errors:
        print(err.line(names(args.command)), file=sys.stderr)
    return 2 if report.errors else 0
