"""``icrsumo train``: train a learned agent on collected data.
Its parser (``add``) and its handler (``run``)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from .registry import Commands


def add(sub: Commands) -> None:
    """Add the parser of ``icrsumo train``."""
    t = sub.add_parser(
        "train", help="train a learned agent on collected data (resumes from OUT/last.pt)",
        description="Behaviour cloning of the expert's plan; config in a TOML file; writes "
        "OUT/train_log.jsonl, OUT/last.pt and OUT/model.pt.",
    )
    t.add_argument("config", help="TOML training config (see icrsumo/learn/checkpoints/*.toml)")
    t.add_argument("--data", required=True, action="append",
                   help="folder written by icrsumo collect (repeatable)")
    t.add_argument("--out", required=True, help="output folder")
    t.add_argument("--augment-instructions", action="store_true",
                   help="train on paraphrase and noise variants from the training bank")
    t.add_argument("--steps", type=int, help="override the config's steps")
    t.add_argument("--seed", type=int, help="override the config's seed")
    t.add_argument("--device", help="auto (default), cpu or cuda")
    t.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="processes computing a pretrained encoder's embeddings of the training texts "
                   "(encoder minilm; default: number of cores)")
    t.add_argument("--quiet", action="store_true",
                   help="no progress on stderr (stages, steps and loss, validation lines)")
    t.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``icrsumo train``; its exit status."""
    from icrsumo.learn.train import read_config, train

    cfg = read_config(Path(args.config), augment_instructions=True if args.augment_instructions else None,
                      steps=args.steps, device=args.device, seed=args.seed)
    m = train(cfg, [Path(d) for d in args.data], Path(args.out), quiet=args.quiet,
              encode_workers=args.workers)
    print(f"step {m.get('step')}: validation {m.get('val', {})} -> {Path(args.out) / 'model.pt'}")
    return 0
