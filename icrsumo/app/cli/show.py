"""``icrsumo show``: replay a stored episode, check it is the same, write its video and a still.
Its parser (``add``) and its handler (``run``)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from icrsumo.core.defaults import DEFAULT_AGENT
from icrsumo.core.errors import InputError, visible
from icrsumo.core.vocab import EpisodeStatus

from .registry import Commands


def add(sub: Commands) -> None:
    """Add the parser of ``icrsumo show``."""
    sh = sub.add_parser(
        "show", help="watch a stored episode: replay it, check it is the same, write its video and a still",
        description="Re-simulate one stored episode of an evaluate (or attack) folder, check that the "
        "replay reproduces the stored log byte for byte, and write the BEV video (WebM: plays in a browser) "
        "with the active instruction and notices, plus a still of the moment it went wrong (the decision "
        "where it left its route or its first infraction, whichever came first; else where it ended). "
        "Exit status 0: the replay is the stored episode, 1: it differs, 2: bad input.",
    )
    sh.add_argument("out", help="the --out folder of icrsumo evaluate or attack")
    sh.add_argument("--agent", help=f"the stored agent name (default {DEFAULT_AGENT})")
    sh.add_argument("--route", required=True, help="route id")
    sh.add_argument("--family", default="baseline", help="baseline (default), a family, attack or transfer")
    sh.add_argument("--k", type=int, default=0, help="the variant (default 0)")
    sh.add_argument("--spec", help="the agent spec, where the folder does not record it (older folders)")
    sh.add_argument("--dir", help="where to write the video and the still (default OUT/show/...)")
    sh.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``icrsumo show``; its exit status."""
    from icrsumo.agents.registry import DEFAULT_AGENT

    from ..show import show_episode

    if args.dir is None and Path(args.out).is_dir() and not os.access(args.out, os.W_OK | os.X_OK):
        raise InputError(args.out, "", "the folder is not writable, so the video and still cannot go to "
                         "OUT/show", "pass --dir FOLDER, a folder you can write to")
    res = show_episode(Path(args.out), args.agent or DEFAULT_AGENT, args.route, args.family, args.k,
                       Path(args.dir) if args.dir else None, spec=args.spec)
    r = res.record
    if r.status == EpisodeStatus.DONE:
        print(f"{r.route_id} {visible(r.agent)} {r.family}:{r.k}  DS {r.ds:.1f}  RC {r.rc:.1f}  "
              f"IS {r.is_:.3f}  {r.termination} ({r.termination_class})")
    else:  # stored with its log up to the crash, unscored in the tables (docs/scoring.md)
        print(f"{r.route_id} {visible(r.agent)} {r.family}:{r.k}  crashed: {visible(r.message[:160])}")
    print("the replay reproduces the stored log byte for byte" if res.identical else
          f"the replay does NOT reproduce the stored log: {res.difference}")
    print(f"video: {res.video}")
    print(f"still at t = {res.moment_t:.1f} s ({res.moment}): {res.still}")
    return 0 if res.identical else 1
