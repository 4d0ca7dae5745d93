"""``icrsumo export-exact``: a trained checkpoint made exact (the same bits on every CPU).
Its parser (``add``) and its handler (``run``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from .registry import Commands


def add(sub: Commands) -> None:
    """Add the parser of ``icrsumo export-exact``."""
    x = sub.add_parser(
        "export-exact", help="make a trained checkpoint exact: the same bits on every CPU, no torch to run",
        description="Quantise a model.pt of icrsumo train to integer weights and activations whose sums "
        "float32 carries exactly (docs/exact.md), calibrated on frames of icrsumo collect folders; "
        "writes OUT (.npz), usable as --agent OUT.",
    )
    x.add_argument("checkpoint", help="model.pt written by icrsumo train")
    x.add_argument("--out", required=True, help="the exact checkpoint to write (NAME.npz)")
    x.add_argument("--calibration", required=True, action="append",
                   help="folder written by icrsumo collect (repeatable): its frames calibrate the scales")
    x.add_argument("--frames", type=int, default=4000,
                   help="calibration frames, evenly spaced (default 4000)")
    x.add_argument("--percentile", type=float, default=99.99,
                   help="percentile of each activation mapped to its top (default 99.99)")
    x.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``icrsumo export-exact``; its exit status."""
    from icrsumo.learn.exact.quantize import export_file

    ck = export_file(Path(args.checkpoint), Path(args.out), [Path(c) for c in args.calibration],
                     frames=args.frames, percentile=args.percentile)
    worst = max(ck.meta["bounds"].values())
    print(f"{args.out}: exact checkpoint of {Path(args.checkpoint).name} ({ck.config.encoder} encoder), "
          f"calibrated on {ck.meta['calibration_frames']} frames and {ck.meta['calibration_texts']} texts; "
          f"largest partial sum {worst} < 2**24")
    return 0
