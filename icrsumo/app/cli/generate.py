"""``icrsumo generate``: baseline instructions and counterfactual variants per route.
Its parser (``add``) and its handler (``run``)."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from icrsumo.core.errors import InputError
from icrsumo.core.vocab import ALL_FAMILIES, FAMILIES

from .options import names
from .registry import Commands


def add(sub: Commands) -> None:
    """Add the parser of ``icrsumo generate``."""
    g = sub.add_parser(
        "generate", help="baseline instructions + counterfactual variants per route",
        description="Write, per converted route, the baseline instruction sequence and K variant "
        f"sequences per family ({', '.join(FAMILIES)}).",
    )
    g.add_argument("scenarios", help="folder written by convert-routes (or one scenario folder)")
    g.add_argument("--out", required=True, help="output folder")
    g.add_argument("--families", nargs="+", default=[",".join(FAMILIES)],
                   help=f"families, space or comma separated: {', '.join(ALL_FAMILIES)} (default: the "
                   f"first {len(FAMILIES)})")
    g.add_argument("--k", type=int, default=8, help="variants per family (default 8)")
    g.add_argument("--seed", type=int, default=2026, help="seed of all draws (default 2026)")
    g.add_argument("--templates", type=Path, help="folder with your own template banks")
    g.add_argument("--baseline-bank", type=Path, metavar="FILE",
                   help="LangAuto's own baseline wording: LMDrive's instruction dictionary (JSON: "
                   "instruction-type id \"0\"..\"64\" -> phrasings with [x]/[y]); its phrasings replace "
                   "icrsumo's for the types they map (see the README)")
    g.add_argument("--generator", choices=["templates", "llm"], default="templates")
    g.add_argument("--endpoint", help="OpenAI-compatible base URL, e.g. http://127.0.0.1:8000/v1")
    g.add_argument("--model", help="model name for --generator llm")
    g.add_argument("--cache", type=Path, help="LLM answer cache (default OUT/llm_cache)")
    g.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    g.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``icrsumo generate``; its exit status."""
    from icrsumo.instructions.generate import GenerateOptions, generate
    from icrsumo.instructions.store import skipped_families

    families = tuple(f for item in args.families for f in item.split(",") if f)
    llm = None
    if args.generator == "llm":
        from icrsumo.instructions.llm import LLMConfig

        if not args.endpoint or not args.model:
            raise InputError("--generator llm", "", "needs --endpoint URL and --model NAME",
                             "give the chat-completions server and model")
        llm = LLMConfig(endpoint=args.endpoint, model=args.model,
                        cache_dir=Path(args.cache or Path(args.out) / "llm_cache"),
                        api_key=os.environ.get("ICRSUMO_LLM_API_KEY"))
    bank = None
    if args.baseline_bank is not None:
        from icrsumo.instructions.baseline_bank import load_baseline_bank

        bank = load_baseline_bank(args.baseline_bank)
        if bank.note():
            print(bank.note(), file=sys.stderr)
    opts = GenerateOptions(families=families, k=args.k, seed=args.seed, templates=args.templates,
                           workers=args.workers, llm=llm, baseline_bank=bank)
    t0 = time.perf_counter()
    written, failures = generate(Path(args.scenarios), Path(args.out), opts, refuse_empty=True)
    skipped = sum(len(fams) for fams in skipped_families(Path(args.out)).values())
    print(f"{len(written)} routes x (1 + {len(families)} x {args.k}) sequences, {skipped} route-family "
          f"pairs skipped (the lines above say why), {len(failures)} failed "
          f"in {time.perf_counter() - t0:.1f} s -> {args.out}", file=sys.stderr)
    for err in failures:
        print(err.line(names(args.command)), file=sys.stderr)
    return 2 if failures else 0
