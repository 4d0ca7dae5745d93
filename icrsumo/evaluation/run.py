"""The orchestration of an evaluation: check the options, resolve the agents (user code is
imported here, once), prepare the suite, plan the jobs, run those not stored yet on the backend
(retrying a crashed episode once), and write the outputs."""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

from ..agents.registry import DEFAULT_AGENT, agent_factory, agent_name
from ..errors import InputError
from ..instructions.families import FAMILIES
from ..store import ResultStore
from ..types import EpisodeRecord
from ..vocab import EpisodeStatus, ErrorKind, OutcomeStatus
from .backends import run_jobs
from .inference import route_jobs, start_inference, stop_inference
from .options import EvalOptions
from .outputs import write_outputs
from .plan import Job, plan_jobs, prepare_suite
from .progress import Progress

#: attempts an episode gets at most
MAX_ATTEMPTS = 2
#: error kinds that are retried (a timed-out agent is not: a retry would wait the whole timeout)
RETRIED = frozenset({ErrorKind.ERROR, ErrorKind.WORKER_DIED})
#: longest stored message of a crashed episode (characters)
MAX_MESSAGE = 2000


@dataclass(frozen=True)
class EvalResult:
    """What an evaluation gave. ``summary``: the contents of OUT/summary.json; ``out``: the
    folder; ``episodes``: episodes of the plan, ``ran``: those run now (the others were stored
    already), ``done`` / ``crashed``: the plan's stored episodes by status; ``inference``: agent
    name -> statistics of its batched inference processes (``batch_inference`` only: resets,
    acts, batches, largest_batch, processes, and the seconds wait_s, io_s, run_s)."""

    summary: dict = field(repr=False)
    out: Path
    episodes: int
    ran: int
    done: int
    crashed: int
    inference: Mapping[str, dict] = field(default_factory=dict)


def resolve_agents(specs: tuple[str, ...]) -> dict[str, Callable]:
    """Spec -> agent factory for every spec (imports user code, asks remote agents for their
    name); InputErrors for bad specs."""
    return {spec: agent_factory(spec) for spec in dict.fromkeys(specs)}


def run_evaluation(opts: EvalOptions) -> EvalResult:
    """Run (or resume) an evaluation and write its reports."""
    opts.check()
    factories = resolve_agents(opts.agents)
    names = {spec: agent_name(spec, f) for spec, f in factories.items()}
    prep = prepare_suite(opts)
    out = Path(opts.out)
    written = set(prep.routes)
    jobs = [j for j in plan_jobs(opts, prep.scenarios, prep.instructions, names) if j.route_id in written]
    with ResultStore(out / "results.sqlite") as store:
        have = store.keys()
        todo = [j for j in jobs if j.key not in have]
        with Progress(len(todo), opts.quiet) as progress:
            servers = start_inference(opts, todo, factories)
            try:
                run_queue(route_jobs(todo, servers), opts, store, progress)
            finally:
                progress.close()
                stats = stop_inference(opts, servers)
        keys = {j.key for j in jobs}
        records = [r for r in store.records() if (r.agent, r.route_id, r.family, r.k, r.seed) in keys]
        summary = write_outputs(opts, out, store, records, prep.scenarios, prep.instructions)
    ep = summary["episodes"]
    return EvalResult(summary=summary, out=out, episodes=len(jobs), ran=len(todo), done=ep["done"],
                      crashed=ep["crashed"], inference=stats)


def run_queue(queue: list[Job], opts: EvalOptions, store: ResultStore, progress: Progress) -> None:
    """Run ``queue`` on the backend, storing each episode at once; an episode that crashed
    (:data:`RETRIED` kinds) is run again once, then stored as crashed; a timed-out one is stored
    at once."""
    attempts: dict[tuple, int] = {}
    while queue:
        retry = []
        for job, outcome in run_jobs(queue, opts):
            n = attempts[job.key] = attempts.get(job.key, 0) + 1
            if outcome.status is OutcomeStatus.DONE:
                store.put(replace(outcome.record, attempts=n), outcome.log_json)
                progress.tick()
            elif n < MAX_ATTEMPTS and outcome.error_kind in RETRIED:
                retry.append(job)
            else:
                store.put(EpisodeRecord(job.agent, job.route_id, job.family, job.k, job.seed,
                                        status=EpisodeStatus.CRASHED, attempts=n,
                                        message=outcome.message[:MAX_MESSAGE]))
                progress.tick()
        queue = retry


def report_only(out: Path, quiet: bool = False) -> dict:
    """Rebuild summary, tables and figures of an evaluation folder from its store (no SUMO);
    returns the summary."""
    out = Path(out)
    cfg_path = out / "config.json"
    if not cfg_path.is_file() or not (out / "results.sqlite").is_file():
        raise InputError(out, "", "not an evaluation folder (no config.json / results.sqlite)",
                         "pass the --out folder of icrsumo evaluate")
    cfg = json.loads(cfg_path.read_text(encoding="utf-8"))
    with ResultStore(out / "results.sqlite") as store:
        records = store.records()
        families = tuple(f for f in FAMILIES if any(r.family == f for r in records))
        agents = tuple(sorted({r.agent for r in records}))
        opts = EvalOptions(out=out, suite=cfg["suite"], agents=agents or (DEFAULT_AGENT,),
                           families=families or FAMILIES, k=int(cfg["k"]), seed=int(cfg["seed"]),
                           traffic=cfg.get("traffic", "normal"), quiet=quiet)
        return write_outputs(opts, out, store, records, out / "scenarios" if (out / "scenarios").is_dir()
                             else Path(cfg["suite"]), out / "instructions")
