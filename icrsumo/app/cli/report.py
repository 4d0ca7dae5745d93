"""``icrsumo report``: rebuild the summary, tables and figures of an evaluation folder.
Its parser (``add``) and its handler (``run``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from icrsumo.scoring import scoring_names

from .registry import Commands


def add(sub: Commands) -> None:
    """Add the parser of ``icrsumo report``."""
    r = sub.add_parser("report", help="rebuild summary, tables and figures of an evaluation folder")
    r.add_argument("out", help="the --out folder of icrsumo evaluate")
    r.add_argument("--quiet", action="store_true")
    r.add_argument("--scoring", choices=scoring_names(), default=None,
                   help="rescore every stored episode from its log by these rules (default: report the "
                   "stored scores)")
    r.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``icrsumo report``; its exit status."""
    from icrsumo.evaluation import report_only

    report_only(Path(args.out), quiet=args.quiet, scoring=args.scoring)
    return 0
