"""``icrsumo evaluate``: the paired ICR protocol, baseline against counterfactual instructions.
Its parser (``add``) and its handler (``run``)."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from icrsumo.core.defaults import DEFAULT_AGENT, DEFAULT_SUITE
from icrsumo.core.vocab import CONTROL_FAMILIES, DELIVERY_FAMILIES, FAMILIES
from icrsumo.scoring import DEFAULT_SCORING, scoring_names

from .options import add_llm_options, add_on_block, add_traffic, agent_specs, split_list, suites
from .registry import Commands


def add(sub: Commands) -> None:
    """Add the parser of ``icrsumo evaluate``."""
    v = sub.add_parser(
        "evaluate", help="the paired ICR protocol: baseline vs counterfactual instructions",
        description="Run every agent on every route with the baseline instructions and K variants "
        "of each family (same scenario, seed, traffic), store each episode at once (resumable), "
        "and write summary.json, tables and figures.",
    )
    v.add_argument("--suite", default=DEFAULT_SUITE,
                   help=f"a bundled suite ({suites()}; default {DEFAULT_SUITE}; "
                   "icrsumo list suites), a route XML file or a convert-routes folder")
    v.add_argument("--agent", action="append",
                   help="built-in name, module:Class, path/file.py:Class, remote:http://HOST:PORT or "
                   f"llm:MODEL@http://HOST:PORT/v1 (repeatable; default {DEFAULT_AGENT})")
    v.add_argument("--family", action="append",
                   help=f"{', '.join(FAMILIES)}, the controls {', '.join(CONTROL_FAMILIES)} and the delivery "
                   f"families {', '.join(DELIVERY_FAMILIES)} (repeatable; default the {len(FAMILIES)})")
    v.add_argument("--k", type=int, default=8, help="variants per family (default 8)")
    v.add_argument("--seed", type=int, default=2026, help="seed of the variant draws (default 2026)")
    v.add_argument("--routes", action="append", help="only these route ids (comma separated)")
    v.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="worker processes, one SUMO each (default: number of cores)")
    v.add_argument("--backend", default="local", help="local (default) or ray")
    v.add_argument("--address", help="Ray cluster address for --backend ray")
    add_traffic(v)
    v.add_argument("--out", default="icr_out", help="output folder (default icr_out)")
    v.add_argument("--rollout-route", help="route of the paired rollout figure (default: the first)")
    v.add_argument("--baseline-bank", type=Path, metavar="FILE",
                   help="LangAuto's own baseline wording: LMDrive's instruction dictionary; part of the "
                   "out folder's configuration (its SHA-256)")
    v.add_argument("--quiet", action="store_true", help="no progress bar or table")
    v.add_argument("--batch-inference", metavar="DEVICE",
                   help="run each non-privileged agent in one inference process on DEVICE (cuda, cpu, "
                   "auto) that batches the observations of all workers (default: every worker runs "
                   "its own agent)")
    v.add_argument("--max-batch", type=int, default=32, metavar="N",
                   help="observations per forward pass with --batch-inference (default 32)")
    v.add_argument("--inference-processes", type=int, default=1, metavar="N",
                   help="inference processes per agent with --batch-inference, each serving a share "
                   "of the workers (default 1)")
    v.add_argument("--agent-timeout", type=float, default=60.0, metavar="S",
                   help="seconds an agent's reset/act call (or a --guard's reset/check) may take before the "
                   "episode is stored as crashed (default 60; 0: no limit)")
    v.add_argument("--scoring", choices=scoring_names(), default=DEFAULT_SCORING,
                   help=f"scoring rules (default {DEFAULT_SCORING}: CARLA Leaderboard 1.0's, rule by rule)")
    v.add_argument("--fail-on-crash", action="store_true",
                   help="exit with status 1 when any episode of the evaluation is stored as crashed (for CI)")
    v.add_argument("--retry-crashed", action="store_true",
                   help="run the episodes stored as crashed again (after a transient fault: a remote "
                   "server that was down, a wrong device)")
    v.add_argument("--replace-agent", action="append", metavar="NAME",
                   help="the out folder holds episodes of another agent of this name (other code or "
                   "checkpoint): delete them and run this one (repeatable)")
    v.add_argument("--guard", action="append", metavar="NAME",
                   help="also run every agent behind this instruction guard, as its own rows "
                   "AGENT+guard:NAME: text, plan, llm:MODEL@URL or a plugin's (repeatable; docs/guards.md)")
    add_on_block(v)
    v.add_argument("--asking", action="store_true",
                   help="agents may ask for clarification: the navigator answers with the route's next "
                   "maneuver 2 simulated seconds later, at most once per maneuver, and every ask is counted; "
                   "part of the out folder's configuration (docs/agents.md)")
    add_llm_options(v)
    v.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``icrsumo evaluate``; its exit status."""
    from ..api import evaluate

    t0 = time.perf_counter()
    routes = split_list(args.routes, "--routes")
    result = evaluate(
        suite=args.suite, agents=agent_specs(args) or None,
        families=split_list(args.family, "--family") or None,
        k=args.k, seed=args.seed, out=args.out, workers=args.workers, quiet=args.quiet,
        routes=routes or None, backend=args.backend, address=args.address,
        traffic=args.traffic, rollout_route=args.rollout_route, agent_timeout=args.agent_timeout or None,
        batch_inference=args.batch_inference, max_batch=args.max_batch,
        inference_processes=args.inference_processes, baseline_bank=args.baseline_bank,
        retry_crashed=args.retry_crashed, scoring=args.scoring,
        replace_agents=split_list(args.replace_agent, "--replace-agent"),
        guards=split_list(args.guard, "--guard"), asking=args.asking, on_block=args.on_block,
    )
    again = (" (left out of every table, with their pairs; --retry-crashed runs them again)"
             if result.crashed else "")
    print(f"{result.ran:,} episodes run now, {result.episodes - result.ran:,} already stored; "
          f"{result.done:,} episodes done, {result.crashed:,} crashed{again}, "
          f"{time.perf_counter() - t0:.0f} s -> {args.out}", file=sys.stderr)
    print(_digest_line(result.digest), file=sys.stderr)
    return 1 if args.fail_on_crash and result.crashed else 0


def _digest_line(digest: object) -> str:
    """The last line of an evaluation: its digest (hex digits only, never text from a file)."""
    from icrsumo.evaluation.digests import shown_digest

    shown = shown_digest(digest)
    if shown == "none":
        return "digest: none (a stored episode log cannot be read: icrsumo digest OUT names it)"
    return f"digest: {shown} (same digest on another machine = every episode the same)"
