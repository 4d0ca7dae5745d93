"""``icrsumo check-agent``: does an agent follow the agent protocol (findings in plain words).
Its parser (``add``) and its handler (``run``)."""

from __future__ import annotations

import argparse
import time

from .registry import Commands


def add(sub: Commands) -> None:
    """Add the parser of ``icrsumo check-agent``."""
    ca = sub.add_parser(
        "check-agent", help="check that an agent follows the agent protocol, in plain words",
        description="Load an agent spec, check reset/act/name/privileged, drive two episodes of a short "
        "bundled scenario with the same seed and report broken actions, exceptions, hangs, "
        "non-determinism and slowness. Exit status 0: fine, 1: problems, 2: bad input.",
    )
    ca.add_argument("spec", help="built-in name, module:Class, path/file.py:Class or remote:http://HOST:PORT")
    ca.add_argument("--route", default="tiny_003", help="bundled tiny route to drive (default tiny_003)")
    ca.add_argument("--timeout", type=float, default=10.0, metavar="S",
                    help="seconds one agent call may take before it counts as hung (default 10)")
    ca.add_argument("--max-act-ms", type=float, default=100.0,
                    help="mean act() time above which the agent is too slow (default 100 ms, real time)")
    ca.add_argument("--decisions", type=int, default=300, help="decisions per run at most (default 300)")
    ca.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``icrsumo check-agent``; its exit status."""
    from ..check_agent import check_agent

    t0 = time.perf_counter()
    rep = check_agent(args.spec, route=args.route, timeout=args.timeout, max_act_ms=args.max_act_ms,
                      max_decisions=args.decisions)
    print(f"icrsumo check-agent {args.spec} (route {rep.route}, baseline instructions)")
    for f in rep.findings:
        tag = "ok     " if f.ok else "PROBLEM" if f.ok is False else "note   "
        print(f"  {tag}  {f.text}")
    n = len(rep.problems)
    if n:
        print(f"{n} problem{'s' if n > 1 else ''} found: fix {'them' if n > 1 else 'it'} before evaluating "
              f"this agent ({time.perf_counter() - t0:.1f} s)")
        return 1
    print(f"the agent follows the protocol ({time.perf_counter() - t0:.1f} s)")
    return 0
