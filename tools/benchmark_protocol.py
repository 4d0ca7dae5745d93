"""The ``--protocol`` section of ``tools/benchmark.py``: a whole ICR protocol for one agent,
profiled, beside the route-oracle's run of the same protocol and bare SUMO stepping the same
episodes, all in one run.

    python tools/benchmark.py --protocol langauto                  # the whole protocol (long)
    python tools/benchmark.py --protocol langauto --suites langauto-tiny --routes 2 --k 1

For each suite (``langauto``: langauto-tiny, langauto-short, langauto-long; ``--suites``: any
bundled suites, ``tiny`` for the default ICR run) the first ``--routes`` routes (default all) are
converted and their instructions generated once (timed apart, not in the runs' walls), then
``icrsumo evaluate`` runs the four families with K = ``--k`` (default 8) and ``--workers``
(default 2) for the agent (``--agent``, default the default agent) and for the route-oracle,
each in a fresh out folder holding the prepared instructions, with ``EvalOptions.profile``: the
workers time their jobs' phases and the parent what happens around them
(:mod:`icrsumo.evaluation.profile`; the episodes are the same, nothing is stored). Bare SUMO
(:func:`benchmark.bare_sumo`: the ego driven by SUMO, no agent, no BEV, no subscriptions) then
steps every episode of the agent's run, on the same scenario and for the same number of steps,
in a pool of as many workers, profiled the same way.

The table: per run, wall s (all suites), episodes, steps, the closed loop's ms per step (its
phases summed over the workers, per step) and the workers' ms per step (workers x wall / steps),
then every phase in worker-seconds and % of workers x wall. The phases add up to workers x wall
by construction; "other" is what none of them covers, and the run is flagged when it exceeds
:data:`TOLERANCE` of it. Then the ratios of issue 48's targets and a histogram of the episodes'
lengths (simulated s) of both runs.
"""

from __future__ import annotations

import multiprocessing
import os
import platform
import shutil
import statistics
import time
import xml.etree.ElementTree as ET
from pathlib import Path

from benchmark import bare_sumo
from cpu import cpu_name

from icrsumo.agents.registry import DEFAULT_AGENT, agent_factory
from icrsumo.core.errors import InputError
from icrsumo.core.resources import bundled_suites, suite_coords
from icrsumo.core.vocab import Phase
from icrsumo.evaluation import EvalOptions, run_evaluation
from icrsumo.evaluation.profile import JobTiming, Round, RunProfile, account
from icrsumo.instructions.families import FAMILIES
from icrsumo.instructions.generate import GenerateOptions, generate
from icrsumo.world.convert import ConvertOptions, convert_routes
from icrsumo.world.scenario import read_scenario

#: protocol name -> its suites
PROTOCOLS = {"langauto": ("langauto-tiny", "langauto-short", "langauto-long")}
ORACLE = "route-oracle"
BARE = "bare SUMO"
SEED = 2026
#: "other" (time no phase covers) may be at most this share of workers x wall
TOLERANCE = 0.01
#: issue 48's targets: the protocol's wall (s, 2 workers), the loop per step against bare SUMO,
#: the agent's ICR run against the route-oracle's
TARGET_WALL_S, TARGET_LOOP_RATIO, TARGET_ORACLE_RATIO = 600.0, 4.0, 1.5
#: the table's phase rows (label, phase), in order
ROWS = (
    ("process start: worker start-up", Phase.WORKER_START),
    ("process start: episode set-up (files, network, sensors)", Phase.EPISODE_SETUP),
    ("process start: agent made (checkpoint), reset", Phase.AGENT_LOAD),
    ("process start: SUMO start, 20 s warm-up, close", Phase.SUMO_START),
    ("SUMO stepping: simulationStep", Phase.SUMO_STEP),
    ("SUMO stepping: moveToXY, frame reads", Phase.SUMO_IO),
    ("control (controller, bicycle model)", Phase.CONTROL),
    ("observation (sensors, progress, instruction, World)", Phase.OBSERVATION),
    ("BEV rendering", Phase.BEV),
    ("agent act", Phase.ACT),
    ("scoring: route criteria per step", Phase.RULES),
    ("scoring: the episode's log", Phase.SCORING),
    ("logging: log columns per step", Phase.RECORDING),
    ("logging: log built, JSON", Phase.LOGGING),
    ("storing (parent stores, sends the next job)", Phase.STORING),
    ("idle workers (no job left)", Phase.IDLE),
    ("parent before the episodes (checks, plan)", Phase.BEFORE),
    ("parent after the episodes (outputs)", Phase.AFTER),
    ("other (not covered)", Phase.OTHER),
)


# --------------------------------------------------------------------------- preparation
def route_file(suite: str, n: int | None, work: Path) -> Path:
    """The bundled ``suite``'s route file, or a copy with its first ``n`` routes."""
    path = bundled_suites()[suite]
    if n is None:
        return path
    tree = ET.parse(path)
    root = tree.getroot()
    for el in root.findall("route")[n:]:
        root.remove(el)
    out = work / f"{suite}_{n}.xml"
    tree.write(out, encoding="utf-8", xml_declaration=True)
    return out


def prepare(suite: str, n: int | None, k: int, workers: int, work: Path) -> dict:
    """The suite converted (as ``icrsumo evaluate`` converts it) and its instructions generated
    (the four families, K = ``k``) into ``work``, each timed."""
    scenarios, instructions = work / "scenarios", work / "instructions"
    work.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rep = convert_routes(route_file(suite, n, work), scenarios,
                         ConvertOptions(coords=suite_coords(suite) or "sumo", workers=workers))
    t1 = time.perf_counter()
    if rep.failures:
        print("\n".join(rep.failures), flush=True)
    generate(scenarios, instructions, GenerateOptions(families=FAMILIES, k=k, seed=SEED))
    t2 = time.perf_counter()
    return {"suite": suite, "scenarios": scenarios, "instructions": instructions,
            "convert_s": t1 - t0, "generate_s": t2 - t1}


# --------------------------------------------------------------------------- runs
def profiled_run(prep: dict, agent: str, k: int, workers: int, out: Path) -> tuple[RunProfile, str | None]:
    """``icrsumo evaluate`` of ``agent`` on the prepared suite (four families, K = ``k``) into a
    fresh ``out`` holding the prepared instructions, with the profile on: the profile and the
    run's digest (the same episodes give the same digest)."""
    shutil.copytree(prep["instructions"], out / "instructions")
    res = run_evaluation(EvalOptions(out=out, suite=str(prep["scenarios"]), agents=(agent,), k=k,
                                     seed=SEED, workers=workers, quiet=True, profile=True))
    if res.crashed:
        print(f"benchmark: {res.crashed} episodes of {agent} crashed ({out})", flush=True)
    return res.profile, res.digest


def bare_task(task: tuple[str, int]) -> JobTiming:
    """One episode of bare SUMO: the scenario read, SUMO started and warmed up, ``steps``
    steps, SUMO closed; timed as a job."""
    scenario, steps = task
    t0 = time.perf_counter()
    sc = read_scenario(Path(scenario))
    t1 = time.perf_counter()
    _, per_step = bare_sumo(sc, steps)
    t2 = time.perf_counter()
    stepping = per_step * steps
    phases = {Phase.EPISODE_SETUP: t1 - t0, Phase.SUMO_STEP: stepping, Phase.SUMO_START: t2 - t1 - stepping}
    return JobTiming(phases, t0, t2, os.getpid(), steps, steps * sc.step_length, scenario)


def bare_run(episodes: tuple[JobTiming, ...], workers: int) -> RunProfile:
    """Bare SUMO stepping every episode of ``episodes`` (same scenario, same steps) in a pool of
    ``workers`` processes, profiled as an evaluation is."""
    tasks = [(e.scenario, e.steps) for e in episodes if e.steps > 0]
    began = time.perf_counter()
    with multiprocessing.get_context("fork").Pool(workers) as pool:
        jobs = tuple(pool.imap_unordered(bare_task, tasks, chunksize=1))
    ended = time.perf_counter()
    return account(began, ended, workers, [Round(began, ended, jobs)])


def merged(profiles: list[RunProfile]) -> RunProfile:
    """Several runs one after another as one: walls, phases and episodes added up."""
    phases: dict[str, float] = {}
    for p in profiles:
        for k, v in p.phases.items():
            phases[k] = phases.get(k, 0.0) + v
    return RunProfile(sum(p.wall_s for p in profiles), profiles[0].slots, phases,
                      tuple(e for p in profiles for e in p.episodes))


def row(p: RunProfile) -> dict:
    """A run's row: wall, episodes, steps, per-step costs and its phases (s and share)."""
    capacity = p.wall_s * p.slots
    steps = max(p.steps, 1)
    return {"wall_s": p.wall_s, "workers": p.slots, "episodes": len(p.episodes), "steps": p.steps,
            "sim_s": sum(e.sim_s for e in p.episodes), "loop_ms_per_step": 1e3 * p.loop_s / steps,
            "worker_ms_per_step": 1e3 * capacity / steps,
            "phases_s": {str(k): v for k, v in p.phases.items()},
            "phases_share": {str(k): v / capacity for k, v in p.phases.items()} if capacity else {},
            "other_share": p.phases.get(Phase.OTHER, 0.0) / capacity if capacity else 0.0,
            "lengths_s": sorted(e.sim_s for e in p.episodes)}


def ratios(res: dict) -> dict:
    """Issue 48's ratios: the protocol's wall for the agent, its loop per step against bare
    SUMO's step, and its runs against the route-oracle's (all suites and per suite)."""
    a, o, b = (res["runs"][k] for k in ("agent", "oracle", "bare"))
    full = res["full_protocol"]
    loop = a["loop_ms_per_step"] / max(b["loop_ms_per_step"], 1e-12)
    oracle = a["wall_s"] / max(o["wall_s"], 1e-12)
    out = {"protocol_wall_s": {"value": a["wall_s"], "target": TARGET_WALL_S,
                               **({"met": a["wall_s"] <= TARGET_WALL_S} if full else {})},
           "loop_per_step_over_bare": {"value": loop, "target": TARGET_LOOP_RATIO,
                                       "met": loop <= TARGET_LOOP_RATIO},
           "agent_over_oracle": {"value": oracle, "target": TARGET_ORACLE_RATIO,
                                 "met": oracle <= TARGET_ORACLE_RATIO}}
    out["agent_over_oracle_by_suite"] = {s: w["agent"] / max(w["oracle"], 1e-12)
                                         for s, w in res["suite_walls"].items()}
    return out


def protocol(suites: tuple[str, ...], agent: str, n: int | None, k: int, workers: int, work: Path,
             log=print) -> dict:
    """The section's measurement (see the module's docstring) as one JSON-able dict."""
    res: dict = {"suites": list(suites), "agent": agent, "routes_per_suite": n or "all", "k": k,
                 "workers": workers, "families": list(FAMILIES), "cpu": cpu_name(), "cores": os.cpu_count(),
                 "python": platform.python_version(), "load_average_start": os.getloadavg(),
                 "full_protocol": n is None and k == 8 and workers == 2, "tolerance": TOLERANCE,
                 "preparation": {}, "suite_walls": {}, "digests": {}}
    runs: dict[str, list[RunProfile]] = {"agent": [], "oracle": []}
    for suite in suites:
        prep = prepare(suite, n, k, workers, work / suite / "prep")
        res["preparation"][suite] = {"convert_s": prep["convert_s"], "generate_s": prep["generate_s"]}
        log(f"{suite}: prepared in {prep['convert_s'] + prep['generate_s']:.1f} s")
        walls = res["suite_walls"][suite] = {}
        digests = res["digests"][suite] = {}
        for key, spec in (("agent", agent), ("oracle", ORACLE)):
            p, digests[key] = profiled_run(prep, spec, k, workers, work / suite / key)
            runs[key].append(p)
            walls[key] = p.wall_s
            log(f"  {spec}: {len(p.episodes)} episodes, {p.wall_s:.1f} s")
    agent_p, oracle_p = merged(runs["agent"]), merged(runs["oracle"])
    log(f"{BARE}: {len(agent_p.episodes)} episodes")
    bare_p = bare_run(agent_p.episodes, workers)
    res["runs"] = {"agent": row(agent_p), "oracle": row(oracle_p), "bare": row(bare_p)}
    res["ratios"] = ratios(res)
    res["load_average_end"] = os.getloadavg()
    return res


# --------------------------------------------------------------------------- output
def _cell(v: float, capacity: float) -> str:
    return f"{v:.1f} ({100 * v / capacity:.1f} %)" if capacity else f"{v:.1f}"


def table(res: dict) -> str:
    """The section's table: one column per run, then the ratios and the histogram."""
    runs = [res["runs"][k] for k in ("agent", "oracle", "bare")]
    la0, la1 = res["load_average_start"][0], res["load_average_end"][0]
    prep = sum(p["convert_s"] + p["generate_s"] for p in res["preparation"].values())
    lines = [f"protocol: {', '.join(res['suites'])}, routes {res['routes_per_suite']} per suite, four "
             f"families, K = {res['k']}, --workers {res['workers']}; CPU {res['cpu']} ({res['cores']} cores, "
             f"load average {la0:.1f} at start, {la1:.1f} at end), Python {res['python']}; preparation "
             f"(conversion, generation; not in the walls) {prep:.1f} s",
             "", f"| | {res['agent']} | {ORACLE} | {BARE} (the agent's episodes) |", "|---|---:|---:|---:|"]

    def add(label: str, cells: list[str]) -> None:
        lines.append(f"| {label} | " + " | ".join(cells) + " |")

    add("wall s", [f"{r['wall_s']:.1f}" for r in runs])
    add("episodes", [str(r["episodes"]) for r in runs])
    add("steps (simulated s)", [f"{r['steps']} ({r['sim_s']:.0f})" for r in runs])
    add("closed loop ms per step (one worker)", [f"{r['loop_ms_per_step']:.3f}" for r in runs])
    add("worker ms per step (workers x wall / steps)", [f"{r['worker_ms_per_step']:.3f}" for r in runs])
    for label, phase in ROWS:
        add(f"{label}, worker-s", [_cell(r["phases_s"].get(phase, 0.0), r["wall_s"] * r["workers"])
                                    for r in runs])
    add(f"phases cover workers x wall (other within {100 * TOLERANCE:.0f} %)",
        ["yes" if abs(r["other_share"]) <= TOLERANCE else f"no ({100 * r['other_share']:.1f} %)"
         for r in runs])
    lines += ["", *ratio_lines(res), "", *histogram(res), ""]
    lines += [f"digest {suite} {key}: {d}" for suite, ds in res.get("digests", {}).items()
              for key, d in ds.items()]
    return "\n".join(lines)


def ratio_lines(res: dict) -> list[str]:
    r = res["ratios"]

    def verdict(v: dict) -> str:
        return "" if "met" not in v else " (met)" if v["met"] else " (missed)"

    w = r["protocol_wall_s"]
    lines = ["ratios (issue 48), one run:",
             f"  protocol wall, {res['agent']}, --workers {res['workers']}: {w['value']:.1f} s "
             f"(target <= {w['target']:.0f} s for the whole protocol{verdict(w)})",
             f"  closed loop per step / bare SUMO per step: {r['loop_per_step_over_bare']['value']:.2f}x "
             f"(target <= {TARGET_LOOP_RATIO:g}x{verdict(r['loop_per_step_over_bare'])})",
             f"  {res['agent']} / {ORACLE}, wall: {r['agent_over_oracle']['value']:.2f}x (target <= "
             f"{TARGET_ORACLE_RATIO:g}x on the default ICR run, --suites tiny"
             f"{verdict(r['agent_over_oracle'])})"]
    lines += [f"    {s}: {v:.2f}x" for s, v in r["agent_over_oracle_by_suite"].items()]
    return lines


def _width(longest: float) -> float:
    for w in (5, 10, 20, 25, 50, 100, 200, 250, 500, 1000):
        if longest / w <= 12:
            return float(w)
    return float(10 ** len(str(int(longest))))


def histogram(res: dict) -> list[str]:
    """Episode lengths (simulated s) of the agent's and the route-oracle's runs: count and
    share of all simulated time per bin (the tail's weight), and the quantiles."""
    a, o = res["runs"]["agent"]["lengths_s"], res["runs"]["oracle"]["lengths_s"]
    if not a:
        return ["episode lengths: no episodes"]
    width = _width(max(a + o))
    lines = [f"episode length (simulated s): | bin | {res['agent']} episodes | its share of simulated time | "
             f"{ORACLE} episodes | its share |", "|---|---:|---:|---:|---:|"]
    total_a, total_o = sum(a) or 1.0, sum(o) or 1.0
    for i in range(int(min(a + o) // width), int(max(a + o) // width) + 1):
        lo, hi = i * width, (i + 1) * width
        ia = [x for x in a if lo <= x < hi]
        io = [x for x in o if lo <= x < hi]
        bar = "#" * round(40 * len(ia) / len(a))
        lines.append(f"| [{lo:.0f}, {hi:.0f}) | {len(ia)} {bar} | {100 * sum(ia) / total_a:.1f} % "
                     f"| {len(io)} | {100 * sum(io) / total_o:.1f} % |")
    for name, xs in ((res["agent"], a), (ORACLE, o)):
        if xs:
            q = statistics.quantiles(xs, n=100, method="inclusive") if len(xs) > 1 else [xs[0]] * 99
            lines.append(f"{name}: median {statistics.median(xs):.1f} s, p90 {q[89]:.1f} s, "
                         f"p99 {q[98]:.1f} s, max {max(xs):.1f} s")
    return lines


def check(args) -> tuple[str, ...]:
    """The suites of ``args`` (``--suites``, else the protocol's); an InputError naming the
    option for a bad value, before anything runs."""
    suites = tuple(s for spec in (args.suites or [",".join(PROTOCOLS[args.protocol])])
                   for s in spec.split(",") if s)
    known = bundled_suites()
    bad = [s for s in suites if s not in known]
    if bad or not suites:
        raise InputError("--suites", bad[0] if bad else "", "not a bundled suite",
                         f"use {', '.join(sorted(known))} (icrsumo list suites)")
    for flag, value, low, high in (("--routes", args.routes, 1, None), ("--k", args.k, 1, 64),
                                   ("--workers", args.workers, 1, None)):
        if value is not None and (value < low or (high is not None and value > high)):
            raise InputError(flag, str(value), "out of range", f"use {low} to {high}" if high else
                             f"use {low} or more")
    agent_factory(args.agent or DEFAULT_AGENT)  # an unknown agent: its InputError now
    return suites


def main(args, log=print) -> dict:
    """``tools/benchmark.py --protocol NAME`` with its options (``args``, :func:`check`ed): the
    measurement in a temporary folder; returns the result (the caller prints the table and the
    JSON line)."""
    import tempfile

    suites = check(args)
    with tempfile.TemporaryDirectory(prefix="icrsumo_bench_") as tmp:
        return protocol(suites, args.agent or DEFAULT_AGENT, args.routes, args.k, args.workers, Path(tmp),
                        log)
