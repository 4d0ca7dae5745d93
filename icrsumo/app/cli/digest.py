"""``icrsumo digest``: one SHA-256 over every stored episode of a run; two runs compared.
Its parser (``add``) and its handler (``run``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .registry import Commands


def add(sub: Commands) -> None:
    """Add the parser of ``icrsumo digest``."""
    dg = sub.add_parser(
        "digest", help="one SHA-256 over every stored episode of a run; compare two runs with it",
        description="Print the digest of an evaluation folder: one SHA-256 over every episode in "
        "OUT/results.sqlite (each one's stored log) and the scoring rules, computed from the store "
        "(summary.json's digest is checked against it); the same digest on another machine means every "
        "episode is the same. With OTHER (a second out folder, or a digest: sha256:HEX or 64 hex digits) "
        "print same or differs, and for two folders the first episode that differs. Exit status 0: "
        "same (or no OTHER), 1: differs, 2: bad input, or folders of different scorings or suites.",
    )
    dg.add_argument("out", help="the --out folder of icrsumo evaluate")
    dg.add_argument("other", nargs="?", help="a second out folder, or a digest (sha256:HEX)")
    dg.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``icrsumo digest``; its exit status."""
    from icrsumo.evaluation.digests import compare, folder_digest

    if args.other is None:
        d = folder_digest(Path(args.out))
        print(d.digest)
        print(f"icrsumo: {len(d.episodes)} stored episodes, scoring {d.scoring}; "
              + ("summary.json holds the same digest" if d.summary_agrees else f"note: {d.summary}"),
              file=sys.stderr)
        return 0
    c = compare(Path(args.out), args.other)
    print("same" if c.same else "differs")
    print(f"  {args.out}: {c.digest}")
    print(f"  {args.other if Path(args.other).exists() else 'given'}: {c.other}")
    if c.first_difference:
        print(f"  first difference: {c.first_difference}")
    return 0 if c.same else 1
