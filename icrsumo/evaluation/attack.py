"""``icrsumo attack``: a seeded, resumable search per route for rewrites of the baseline
instructions that make a given agent fail.

The space (:func:`icrsumo.instructions.rewrites.rewrite_pool`): per instruction, the paraphrase
bank's entries of its intent, noise operations on its text and on those paraphrases, every one
classifying as the baseline intent (``--constraint goal``, the default); ``--constraint
misleading`` adds the misleading bank's entries. The method is a (1+1) evolutionary search: the
current sequence starts as the baseline; each query changes one instruction (a position drawn
among those with rewrites, then a rewrite drawn from its pool, both with a Generator seeded by
(seed, route, agent)), runs the closed-loop episode, and keeps the new sequence when its DS is
no higher than the current one's. A route counts where the agent's baseline episode completes;
the attack succeeds on it when a query's episode does not (RD or TO). Every query is a real
episode stored like any other (family ``attack``, k = the query, 1 .. budget), so a rerun, or a
larger budget, replays the search from the store and runs only what is missing. The worst
rewrite found for each agent and route is then driven by the other agents (family
``transfer``, k = a stable id of the agent it was found for).
"""

from __future__ import annotations

import statistics
import sys
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from icrsumo.agents.registry import DEFAULT_AGENT
from icrsumo.core.errors import Field, InputError
from icrsumo.core.fsio import FolderLock, bounded_name, dumps_json, write_atomic
from icrsumo.core.types import Instruction, InstructionSet
from icrsumo.core.vocab import Family
from icrsumo.instructions.banks import load_banks
from icrsumo.instructions.rewrites import rewrite_pool
from icrsumo.instructions.store import read_route_file, route_document
from icrsumo.results.store import ResultStore
from icrsumo.results.summary import Summary
from icrsumo.world.convert import safe_name

from .options import EvalOptions
from .plan import Job, plan_jobs, prepare_suite
from .progress import Progress
from .run import (
    bind_agents,
    bind_guards,
    check_agents,
    claim_agents,
    identify_agents,
    resolve_agents,
    resolve_guards,
    run_queue,
    with_factories,
)

#: queries per route by default: the cost of the paper's fixed grid (4 families x 8 variants)
BUDGET = 32
CONSTRAINTS = ("goal", "misleading")


@dataclass(frozen=True)
class AttackOptions:
    """One attack: ``suite``, ``agents``, ``routes`` (None: all), ``seed`` and ``traffic`` as in
    ``evaluate``; ``budget`` queries (episodes) per agent and route; ``constraint`` goal (meaning
    kept) or misleading (the misleading bank too); ``compare``: an ``evaluate`` out folder on the
    same suite whose fixed grid (paraphrase and noise) is reported beside the search."""

    out: Path
    suite: str = "tiny"
    agents: tuple[str, ...] = (DEFAULT_AGENT,)
    routes: tuple[str, ...] | None = None
    seed: int = 2026
    budget: int = BUDGET
    constraint: str = "goal"
    workers: int = 1
    traffic: str = "normal"
    quiet: bool = True
    compare: Path | None = None
    agent_timeout: float | None = 60.0
    #: agent names whose stored episodes of another agent of that name are deleted and run again
    replace_agents: tuple[str, ...] = ()
    #: instruction guards: every agent is also attacked behind each (rows ``AGENT+guard:NAME``)
    guards: tuple[str, ...] = ()
    #: what an instruction a guard blocks leaves the agent (as evaluate's ``on_block``)
    on_block: str = "keep"

    def eval_options(self) -> EvalOptions:
        """The evaluation options of the out folder (K = 1: the generated variants go unused)."""
        return EvalOptions(
            out=Path(self.out),
            suite=self.suite,
            agents=self.agents,
            families=(),
            k=1,
            seed=self.seed,
            routes=self.routes,
            workers=self.workers,
            traffic=self.traffic,
            quiet=self.quiet,
            agent_timeout=self.agent_timeout,
            replace_agents=self.replace_agents,
            guards=self.guards,
            on_block=self.on_block,
        )

    def check(self) -> None:
        if not 1 <= self.budget <= 1024:
            raise InputError(Field("budget"), str(self.budget), "out of range", "use 1 to 1024 (default 32)")
        if self.constraint not in CONSTRAINTS:
            raise InputError(Field("constraint"), self.constraint, "unknown constraint",
                             "use goal or misleading")
        if self.compare is not None and not (Path(self.compare) / "results.sqlite").is_file():
            raise InputError(
                Field("compare"),
                str(self.compare),
                "not an evaluate out folder (no results.sqlite)",
                f"pass the {Field('out')} folder of an icrsumo evaluate run on the same suite",
            )
        if self.compare is not None:  # read before any episode runs: its grid ends the report
            Summary.read(Path(self.compare) / "summary.json")
        replace(self.eval_options(), families=("paraphrase",)).check()


@dataclass
class _Search:
    """The search of one agent on one route."""

    spec: str
    agent: str
    route: str
    scenario: str
    baseline: InstructionSet
    maneuvers: tuple
    pools: dict[int, tuple[tuple[str, str], ...]]
    rng: np.random.Generator
    base_ds: float
    current: dict[int, int] = field(default_factory=dict)  # position -> pool index
    current_ds: float = 0.0
    sets: list[InstructionSet] = field(default_factory=list)
    results: list[tuple[int, float, str]] = field(default_factory=list)  # (query, DS, termination class)
    first_success: int | None = None
    pending: dict[int, int] = field(default_factory=dict)  # the choice of the query under way
    #: the route's baseline job: the search's episodes are it with other instructions
    job: Job | None = None

    def propose(self, q: int) -> InstructionSet:
        positions = sorted(self.pools)
        pos = positions[int(self.rng.integers(len(positions)))]
        pool = self.pools[pos]
        pick = int(self.rng.integers(len(pool)))
        if pick == self.current.get(pos) and len(pool) > 1:
            pick = (pick + 1) % len(pool)
        choice = {**self.current, pos: pick}
        self.pending = choice
        return InstructionSet(
            self.route,
            Family.ATTACK,
            q,
            self.baseline.seed,
            tuple(_rewritten(ins, self.pools, choice) for ins in self.baseline.instructions),
            self.baseline.notices,
        )


def _rewritten(ins: Instruction, pools: dict, choice: dict[int, int]) -> Instruction:
    if ins.id not in choice:
        return replace(ins, template="keep", source=ins.text)
    text, tid = pools[ins.id][choice[ins.id]]
    return replace(
        ins, text=text, template=tid, source=ins.text, distance=ins.distance if "[x]" in text else None
    )


def agent_folder(name: str) -> str:
    """The folder name of an agent's searched instruction files (bounded in length)."""
    return bounded_name(safe_name(name), name)


def _agent_id(name: str) -> int:
    return zlib.crc32(name.encode("utf-8")) & 0x7FFFFFFF


def _write_sets(path: Path, s: _Search, extra: list[InstructionSet]) -> None:
    meta = {"seed": s.baseline.seed, "k": len(s.sets), "families": ["attack"], "generator": "attack"}
    write_atomic(path, dumps_json(route_document(s.baseline, s.sets + extra, list(s.maneuvers), meta)))


def run_attack(opts: AttackOptions) -> dict:
    """Run (or resume) the attack; writes OUT/attack.json and OUT/attack.md and returns the
    attack document."""
    opts.check()
    eopts = opts.eval_options()
    factories = resolve_agents(opts.agents)
    guards = resolve_guards(opts.guards)
    ids = identify_agents(factories, opts.replace_agents, guards, opts.on_block)
    eopts = replace(eopts, agents=ids.specs)
    out = Path(opts.out)
    with FolderLock(out):
        return _attack_locked(opts, eopts, factories, guards, ids)


def _attack_locked(opts: AttackOptions, eopts: EvalOptions, factories: dict, guards: dict, ids) -> dict:
    names = dict(ids.names)
    out = Path(opts.out)
    check_agents(out / "results.sqlite", ids, opts.replace_agents)
    factories = bind_agents(factories, out)
    bound_guards = bind_guards(guards, out)
    prep = prepare_suite(eopts, ids.config(), {"run": "attack", "constraint": opts.constraint})
    for line in prep.skipped:
        print(f"icrsumo: skipped: {line}", file=sys.stderr)
    jobs = with_factories([
        j for j in plan_jobs(eopts, prep.scenarios, prep.instructions, names, ids.guard_names)
        if j.route_id in prep.routes
    ], factories, bound_guards)
    banks = load_banks(None)
    with ResultStore(out / "results.sqlite", verify=False) as store:  # checked above
        claim_agents(store, ids, opts.replace_agents)
        have = store.keys()
        with Progress(len(jobs) * (opts.budget + 1), opts.quiet) as progress:
            run_queue([j for j in jobs if j.key not in have], eopts, store, progress)
            baselines = _baselines(store)
            searches = []
            for j in jobs:
                b = baselines.get((j.agent, j.route_id))
                if b is None or b.status != "done" or b.termination_class != "done":
                    continue
                f = prep.instructions / f"{safe_name(j.route_id)}.json"
                sets, maneuvers = read_route_file(f)
                base = sets[0]
                pools = {
                    ins.id: p
                    for ins in base.instructions
                    if (p := rewrite_pool(ins, banks, opts.seed, j.route_id, opts.constraint == "misleading"))
                }
                if not pools:
                    continue
                rng = np.random.default_rng([opts.seed, zlib.crc32(j.route_id.encode()), _agent_id(j.agent)])
                searches.append(
                    _Search(
                        j.agent_spec,
                        j.agent,
                        j.route_id,
                        j.scenario,
                        base,
                        maneuvers,
                        pools,
                        rng,
                        b.ds,
                        current_ds=b.ds,
                        job=j,
                    )
                )
            folder = out / "attack" / opts.constraint
            for q in range(1, opts.budget + 1):
                batch = []
                for s in searches:
                    s.sets.append(s.propose(q))
                    path = folder / agent_folder(s.agent) / f"{safe_name(s.route)}.json"
                    _write_sets(path, s, [])
                    batch.append(replace(s.job, family=Family.ATTACK.value, k=q, instructions=str(path)))
                have = store.keys()
                todo = [j for j in batch if j.key not in have]
                for _ in range(len(batch) - len(todo)):
                    progress.tick()
                run_queue(todo, eopts, store, progress)
                recs = {(r.agent, r.route_id, r.k): r for r in store.records(Family.ATTACK)}
                for s in searches:
                    r = recs[(s.agent, s.route, q)]
                    ds = r.ds if r.status == "done" else s.current_ds + 1.0  # a crash is no progress
                    s.results.append((q, ds, str(r.termination_class) if r.status == "done" else "crashed"))
                    if r.status == "done" and r.termination_class != "done" and s.first_success is None:
                        s.first_success = q
                    if ds <= s.current_ds:
                        s.current, s.current_ds = s.pending, ds
        transfer = _transfer(opts, eopts, store, searches, jobs, folder)
        doc = _document(opts, names, searches, transfer, jobs, _baselines(store))
    write_atomic(out / "attack.json", dumps_json(doc))
    write_atomic(out / "attack.md", attack_table(doc))
    return doc


def _baselines(store: ResultStore) -> dict[tuple[str, str], object]:
    return {(r.agent, r.route_id): r for r in store.records(Family.BASELINE)}


def _worst(s: _Search) -> tuple[int, float]:
    """(query, DS) of the lowest-DS episode of a search (the first of equals)."""
    q, ds, _ = min(s.results, key=lambda x: (x[1], x[0]))
    return q, ds


def _transfer(
    opts: AttackOptions,
    eopts: EvalOptions,
    store: ResultStore,
    searches: list[_Search],
    jobs: list[Job],
    folder: Path,
) -> dict:
    """Drive each agent's worst rewrite per route with every other agent (family transfer)."""
    agents = sorted({j.agent for j in jobs})
    if len(agents) < 2:
        return {}
    job_of = {j.agent: j for j in jobs}
    base = _baselines(store)
    batch = []
    for s in searches:
        q, _ = _worst(s)
        worst = replace(s.sets[q - 1], family=Family.TRANSFER, k=_agent_id(s.agent))
        path = folder / "transfer" / agent_folder(s.agent) / f"{safe_name(s.route)}.json"
        write_atomic(
            path,
            dumps_json(
                route_document(
                    s.baseline,
                    [worst],
                    list(s.maneuvers),
                    {"seed": s.baseline.seed, "k": 1, "families": ["transfer"], "generator": "attack"},
                )
            ),
        )
        for other in agents:
            b = base.get((other, s.route))
            if other != s.agent and b is not None and b.status == "done" and b.termination_class == "done":
                batch.append(replace(job_of[other], route_id=s.route, scenario=s.scenario,
                                     family=Family.TRANSFER.value, k=_agent_id(s.agent),
                                     instructions=str(path)))
    have = store.keys()
    with Progress(len(batch), opts.quiet) as progress:
        run_queue([j for j in batch if j.key not in have], eopts, store, progress)
    recs = {(r.agent, r.route_id, r.k): r for r in store.records(Family.TRANSFER)}
    table: dict[str, dict[str, dict]] = {}
    for j in batch:
        source = next(a for a in agents if _agent_id(a) == j.k)
        r = recs[(j.agent, j.route_id, j.k)]
        cell = table.setdefault(source, {}).setdefault(j.agent, {"routes": 0, "failed": 0})
        cell["routes"] += 1
        cell["failed"] += int(r.status == "done" and r.termination_class != "done")
    for row in table.values():
        for cell in row.values():
            cell["success_rate"] = round(cell["failed"] / cell["routes"], 4) if cell["routes"] else None
    return table


def _grid(compare: Path | None, agent: str) -> dict | None:
    """The fixed grid's goal-preserving families of ``agent`` in an evaluate folder: their
    worst ΔDS and the routes any of their variants broke."""
    if compare is None:
        return None
    summary = Summary.read(Path(compare) / "summary.json")
    a = summary.agents.get(agent)
    fams = a.families if a is not None else {}
    with ResultStore(Path(compare) / "results.sqlite", readonly=True) as store:
        recs = [r for r in store.records() if r.agent == agent]
    done = {r.route_id for r in recs if r.family == Family.BASELINE and r.termination_class == "done"}
    broken = sorted(
        {
            r.route_id
            for r in recs
            if r.family in (Family.PARAPHRASE, Family.NOISE)
            and r.route_id in done
            and r.status == "done"
            and r.termination_class != "done"
        }
    )
    return {f: {"worst_dDS": fams[f].worst_d_ds} for f in ("paraphrase", "noise") if f in fams} | {
        "broken_routes": broken
    }


def _document(
    opts: AttackOptions, names: dict, searches: list[_Search], transfer: dict, jobs: list[Job], base: dict
) -> dict:
    agents: dict[str, dict] = {}
    for agent in sorted(set(names.values()) | {j.agent for j in jobs}):  # guarded rows too
        mine = [s for s in searches if s.agent == agent]
        completed = [
            j.route_id
            for j in jobs
            if j.agent == agent
            and (b := base.get((agent, j.route_id)))
            and b.status == "done"
            and b.termination_class == "done"
        ]
        routes = {}
        for s in mine:
            q, ds = _worst(s)
            routes[s.route] = {
                "baseline_DS": round(s.base_ds, 4),
                "first_success": s.first_success,
                "worst_DS": round(ds, 4),
                "worst_dDS": round(ds - s.base_ds, 4),
                "worst_query": q,
                "queries": len(s.results),
                "instructions": [
                    {"id": i.id, "text": i.text, "template": i.template} for i in s.sets[q - 1].instructions
                ],
            }
        wins = [s.first_success for s in mine if s.first_success is not None]
        grid = _grid(opts.compare, agent)
        agents[agent] = {
            "routes_searched": len(mine),
            "routes_completed_by_baseline": len(completed),
            "successes": len(wins),
            "success_rate": round(len(wins) / len(mine), 4) if mine else None,
            "median_queries": statistics.median(wins) if wins else None,
            "worst_dDS": round(float(np.mean([r["worst_dDS"] for r in routes.values()])), 4)
            if routes
            else None,
            "grid": grid,
            "broken_not_by_grid": None
            if grid is None
            else sorted(
                s.route for s in mine if s.first_success is not None and s.route not in grid["broken_routes"]
            ),
            "routes": routes,
        }
    return {
        "suite": opts.suite,
        "seed": opts.seed,
        "budget": opts.budget,
        "constraint": opts.constraint,
        "method": "(1+1) evolutionary search over one-instruction rewrites, seeded per route and agent",
        "agents": agents,
        "transfer": transfer,
    }


def attack_table(doc: dict) -> str:
    """Markdown: per agent the success rate, median queries, worst ΔDS (and the fixed grid's),
    then the transfer table."""
    from icrsumo.reporting.cells import md_cell

    md = [
        f"Attack on {doc['suite']} (constraint {doc['constraint']}, budget {doc['budget']} per route, "
        f"seed {doc['seed']})",
        "",
        "| Agent | routes | successes | success rate % | median queries | worst ΔDS | grid worst ΔDS "
        "(paraphrase / noise) | broken where the grid did not |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for agent, a in doc["agents"].items():
        g = a["grid"]
        grid = (
            "—"
            if g is None
            else " / ".join(
                "—" if g.get(f) is None or g[f]["worst_dDS"] is None else f"{g[f]['worst_dDS']:+.1f}"
                for f in ("paraphrase", "noise")
            )
        )
        rate = "—" if a["success_rate"] is None else f"{100 * a['success_rate']:.1f}"
        worst = "—" if a["worst_dDS"] is None else f"{a['worst_dDS']:+.1f}"
        med = "—" if a["median_queries"] is None else f"{a['median_queries']:g}"
        beyond = "—" if a["broken_not_by_grid"] is None else str(len(a["broken_not_by_grid"]))
        md.append(
            f"| {md_cell(agent)} | {a['routes_searched']} | {a['successes']} | {rate} | {med} | {worst} | "
            f"{grid} | {beyond} |"
        )
    if doc["transfer"]:
        md += [
            "",
            "Transfer: the worst rewrite found for the row's agent, driven by the column's agent "
            "(share of routes it fails, among those whose baseline it completes):",
            "",
        ]
        cols = sorted({c for row in doc["transfer"].values() for c in row})
        md += ["| found for | " + " | ".join(md_cell(c) for c in cols) + " |", "|---|" + "---:|" * len(cols)]
        for src, row in doc["transfer"].items():
            md.append(
                f"| {md_cell(src)} | "
                + " | ".join(
                    "—" if c not in row else f"{100 * row[c]['success_rate']:.0f} % of {row[c]['routes']}"
                    for c in cols
                )
                + " |"
            )
    return "\n".join(md) + "\n"
