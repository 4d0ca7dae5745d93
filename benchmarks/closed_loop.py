"""Closed-loop cost vs SUMO alone, measured in one run on the same scenario.

For a bundled scenario (converted with normal traffic) this times, per simulation step:

- SUMO alone: libsumo stepping the scenario's traffic (same seed, same number of steps after
  the warm-up as the episode), no ego;
- the closed loop with each privileged agent (route-oracle, instruction-follower): BEV render
  at 10 Hz, the agent, the controller, the bicycle model, moveToXY, SUMO's step and all
  infraction checks.

It prints a table and one JSON line with medians (and min / max) over ``--repeats`` runs and
the ratio closed-loop / SUMO-alone per step. Timings are machine-dependent; compare ratios.

    python benchmarks/closed_loop.py [--route tiny_004] [--repeats 5]
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import tempfile
import time
from pathlib import Path

from icrsumo.agents.registry import make_agent
from icrsumo.convert import ConvertOptions, convert_routes
from icrsumo.instructions.generate import GenerateOptions, generate
from icrsumo.instructions.store import read_instruction_sets
from icrsumo.resources import bundled_suites
from icrsumo.runner import run_episode
from icrsumo.scenario import read_scenario
from icrsumo.sim import SumoSession


def bare_sumo(sc, n_steps: int) -> tuple[float, float]:
    """(seconds for start + warm-up, seconds per step after the warm-up) of SUMO alone."""
    t0 = time.perf_counter()
    with SumoSession(sc) as sim:
        sim.run_until(sc.ego_depart)
        t1 = time.perf_counter()
        sim.step(n_steps)
        t2 = time.perf_counter()
    return t1 - t0, (t2 - t1) / n_steps


def closed_loop(sc, instructions, agent_name: str) -> tuple[float, int]:
    """(wall seconds of the whole episode, steps driven)."""
    t0 = time.perf_counter()
    log = run_episode(sc, instructions, make_agent(agent_name))
    return time.perf_counter() - t0, len(log.t)


def _stats(xs: list[float]) -> dict:
    return {"median": statistics.median(xs), "min": min(xs), "max": max(xs)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--route", default="tiny_004")
    ap.add_argument("--split", default="tiny")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        convert_routes(bundled_suites()[args.split], out / "sc", ConvertOptions(workers=2))
        sc = read_scenario(out / "sc" / "scenarios" / args.route)
        generate(out / "sc" / "scenarios" / args.route, out / "instr",
                 GenerateOptions(families=("noise",), k=1))
        baseline = read_instruction_sets(out / "instr" / f"{args.route}.json")[0]
        rows = {}
        ratios = {}
        for agent in ("route-oracle", "instruction-follower"):
            walls, bares, steps = [], [], 0
            for _ in range(args.repeats):
                wall, steps = closed_loop(sc, baseline, agent)
                warm, per_step = bare_sumo(sc, steps)
                walls.append((wall - warm) / steps)
                bares.append(per_step)
            rows[agent] = {"closed_loop_ms": _stats([w * 1e3 for w in walls]),
                           "sumo_alone_ms": _stats([b * 1e3 for b in bares]), "steps": steps}
            ratios[agent] = statistics.median(w / b for w, b in zip(walls, bares))
    print(f"scenario {args.route} ({sc.town}, {sc.length:.0f} m, normal traffic), "
          f"{args.repeats} repeats, {platform.processor() or platform.machine()}")
    print(f"{'agent':<22}{'SUMO alone ms/step':>20}{'closed loop ms/step':>22}{'ratio':>8}")
    for agent, r in rows.items():
        print(f"{agent:<22}{r['sumo_alone_ms']['median']:>20.3f}{r['closed_loop_ms']['median']:>22.3f}"
              f"{ratios[agent]:>8.2f}")
    print(json.dumps({"route": args.route, "repeats": args.repeats, "agents": rows,
                      "ratio_closed_loop_over_sumo": ratios}))


if __name__ == "__main__":
    main()
