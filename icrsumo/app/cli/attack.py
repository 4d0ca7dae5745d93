"""``icrsumo attack``: search for instruction rewrites that make an agent fail.
Its parser (``add``) and its handler (``run``)."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from icrsumo.core.defaults import DEFAULT_AGENT, DEFAULT_SUITE

from .options import add_llm_options, add_on_block, add_traffic, agent_specs, split_list
from .registry import Commands


def add(sub: Commands) -> None:
    """Add the parser of ``icrsumo attack``."""
    at = sub.add_parser(
        "attack", help="search for instruction rewrites that make an agent fail (resumable)",
        description="Per route, a seeded (1+1) evolutionary search over rewrites of the baseline "
        "instructions (paraphrase bank entries and noise operations that keep the meaning; --constraint "
        "misleading adds the misleading bank), each candidate scored by a real closed-loop episode stored "
        "like any other; writes OUT/attack.json and OUT/attack.md, with a transfer table between agents.",
    )
    at.add_argument("--suite", default=DEFAULT_SUITE, help=f"as for evaluate (default {DEFAULT_SUITE})")
    at.add_argument("--agent", action="append", help=f"as for evaluate (repeatable; default {DEFAULT_AGENT})")
    at.add_argument("--routes", action="append", help="only these route ids (comma separated)")
    at.add_argument("--seed", type=int, default=2026, help="seed of the search and the suite (default 2026)")
    at.add_argument("--budget", type=int, default=32,
                    help="queries (episodes) per agent and route (default 32)")
    at.add_argument("--constraint", choices=["goal", "misleading"], default="goal",
                    help="goal: rewrites keep the meaning (default); misleading: the misleading bank too")
    at.add_argument("--compare", type=Path, metavar="EVAL_OUT",
                    help="an evaluate out folder on the same suite: its fixed grid beside the search")
    at.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="worker processes")
    add_traffic(at)
    at.add_argument("--agent-timeout", type=float, default=60.0, metavar="S",
                    help="seconds an agent call may take (default 60; 0: no limit)")
    add_llm_options(at)
    at.add_argument("--out", default="attack_out", help="output folder (default attack_out)")
    at.add_argument("--quiet", action="store_true", help="no progress bar or table")
    at.add_argument("--replace-agent", action="append", metavar="NAME",
                    help="the out folder holds episodes of another agent of this name (other code or "
                    "checkpoint): delete them and run this one (repeatable)")
    at.add_argument("--guard", action="append", metavar="NAME",
                    help="also attack every agent behind this instruction guard (as evaluate's; repeatable)")
    add_on_block(at)
    at.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``icrsumo attack``; its exit status."""
    from icrsumo.evaluation.attack import AttackOptions, attack_table, run_attack

    t0 = time.perf_counter()
    routes = split_list(args.routes, "--routes")
    agents = agent_specs(args) or None
    timeout = None if args.agent_timeout == 0 else args.agent_timeout
    opts = AttackOptions(out=Path(args.out), suite=args.suite, seed=args.seed, budget=args.budget,
                         routes=routes or None, constraint=args.constraint,
                         workers=args.workers, traffic=args.traffic, quiet=args.quiet, compare=args.compare,
                         agent_timeout=timeout,
                         replace_agents=split_list(args.replace_agent, "--replace-agent"),
                         guards=split_list(args.guard, "--guard"), on_block=args.on_block,
                         **({"agents": agents} if agents else {}))
    doc = run_attack(opts)
    if not args.quiet:
        print(attack_table(doc))
    print(f"attack: {sum(a['successes'] for a in doc['agents'].values())} routes broken, "
          f"{time.perf_counter() - t0:.0f} s -> {args.out}", file=sys.stderr)
    return 0
