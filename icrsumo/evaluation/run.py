"""The orchestration of an evaluation: check the options, resolve the agents (user code is
imported here, once), prepare the suite, plan the jobs, run those not stored yet on the backend
(retrying a crashed episode once), and write the outputs."""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

from icrsumo.agents.registry import (
    DEFAULT_AGENT,
    LLM_PREFIX,
    PYTHON_PREFIX,
    agent_factory,
    agent_name,
    python_agent,
)
from icrsumo.core.errors import Field, InputError, display_url, note, short, visible
from icrsumo.core.fsio import FolderLock
from icrsumo.core.types import EpisodeRecord
from icrsumo.core.vocab import EpisodeStatus, ErrorKind, OutcomeStatus
from icrsumo.guards.base import guarded_fingerprint, guarded_name, split_policy
from icrsumo.instructions.families import ALL_FAMILIES, FAMILIES
from icrsumo.results.store import ResultStore
from icrsumo.results.summary import Summary
from icrsumo.scoring import SCORINGS, score_episode, scoring_names

from .backends import run_jobs
from .inference import route_jobs, start_inference, stop_inference
from .options import EvalOptions
from .outputs import write_outputs
from .plan import Job, longest_first, no_routes, plan_jobs, prepare_suite, read_config, skip_reason
from .profile import ProfileSink, RunProfile
from .progress import Progress

#: attempts an episode gets at most
MAX_ATTEMPTS = 2
#: error kinds that are retried (a timed-out agent is not: a retry would wait the whole timeout)
RETRIED = frozenset({ErrorKind.ERROR, ErrorKind.WORKER_DIED})
#: longest stored message of a crashed episode (characters)
MAX_MESSAGE = 2000
#: longest agent or guard name (characters; a route id may have 200 too)
MAX_NAME = 200


@dataclass(frozen=True)
class EvalResult:
    """What an evaluation gave. ``stats``: OUT/summary.json as a typed
    :class:`icrsumo.results.summary.Summary` (``stats.agents[NAME].baseline.ds``); ``summary``: the same
    as summary.json's plain mapping (``summary["agents"][NAME]["baseline"]["DS"]``); ``out``: the
    folder; ``episodes``: episodes of the plan, ``ran``: those run now (the others were stored
    already), ``done`` / ``crashed``: the plan's stored episodes by status; ``inference``: agent
    name -> statistics of its batched inference processes (``batch_inference`` only: resets,
    acts, batches, largest_batch, processes, and the seconds wait_s, io_s, run_s); ``profile``:
    where the run's wall time went (``opts.profile`` only, :mod:`icrsumo.evaluation.profile`;
    never stored); ``digest``: the summary's digest."""

    stats: Summary = field(repr=False)
    out: Path
    episodes: int
    ran: int
    done: int
    crashed: int
    inference: Mapping[str, dict] = field(default_factory=dict)
    profile: RunProfile | None = None

    @property
    def summary(self) -> dict:
        """summary.json's mapping (a new dict each time: :meth:`icrsumo.results.summary.Summary.to_dict`)."""
        return self.stats.to_dict()

    @property
    def digest(self) -> str | None:
        """The run's digest (``stats.digest``: every stored episode and the scoring,
        :mod:`icrsumo.evaluation.digests`), None when a damaged stored log leaves the store without one."""
        return self.stats.digest


def resolve_agents(specs: tuple) -> dict[str, Callable]:
    """Spec -> agent factory for every spec (imports user code, asks remote agents for their
    name, calls an agent class's ``check_ready()`` when it has one); InputErrors for bad specs.
    An agent given as a Python object (a class, a function making agents, an instance: the
    Python API) is keyed by its label (:func:`icrsumo.agents.registry.python_agent`)."""
    out: dict[str, Callable] = {}
    seen: dict[int, str] = {}  # id of an object given -> its label (the same object twice runs once)
    for i, spec in enumerate(specs):
        if isinstance(spec, str):
            if spec not in out:
                out[spec] = agent_factory(spec)
                check = getattr(getattr(out[spec], "agent_class", out[spec]), "check_ready", None)
                if callable(check):  # what a worker would fail on, said before any episode runs
                    check()
        elif id(spec) not in seen:
            label, factory = python_agent(spec, f"agents[{i}]")
            base, n = label, 2
            while label in out:  # another object of the same class or name: its own label
                label, n = f"{base} #{n}", n + 1
            seen[id(spec)] = label
            out[label] = factory
    return out


def bind_agents(factories: Mapping[str, Callable], out: Path) -> dict[str, Callable]:
    """``factories`` with each one that keeps state in the out folder (a ``bind(out)`` method:
    an LLM agent's response cache) bound to ``out``; binding checks what such an agent needs
    (its server, its API key variable), before anything is written."""
    return {spec: f.bind(out) if callable(getattr(type(f), "bind", None)) else f
            for spec, f in factories.items()}


def carries_factory(spec: str) -> bool:
    """Whether a job of agent ``spec`` must carry its factory: an agent given as a Python object,
    or one bound to the out folder (an LLM agent); the workers cannot build those from a spec."""
    return spec.startswith((PYTHON_PREFIX, LLM_PREFIX))


def with_factories(jobs: list[Job], factories: Mapping[str, Callable],
                   guards: Mapping[str, Callable] | None = None) -> list[Job]:
    """``jobs`` with their factory where they must carry it (:func:`carries_factory`), and with
    their guard's factory where it is bound to the out folder (an LLM guard: ``guards``)."""
    guards = guards or {}
    jobs = [replace(j, factory=factories[j.agent_spec]) if carries_factory(j.agent_spec) else j for j in jobs]
    return [replace(j, guard_factory=guards[j.guard]) if j.guard in guards else j for j in jobs]


def bind_guards(guards: Mapping[str, Callable], out: Path) -> dict[str, Callable]:
    """The guards bound to the out folder (those with a ``bind(out)`` method: an LLM guard's
    response cache), by spec; the others are built by the workers from their spec."""
    return {spec: f.bind(out) for spec, f in guards.items() if callable(getattr(type(f), "bind", None))}


def resolve_guards(specs: tuple[str, ...]) -> dict[str, Callable]:
    """Guard spec -> guard factory for every spec (:func:`icrsumo.guards.registry.guard_factory`);
    an InputError for an unknown one, before any episode runs."""
    from icrsumo.guards.registry import guard_factory

    out: dict[str, Callable] = {}
    for spec in specs:
        if spec not in out:
            out[spec] = guard_factory(spec)
    return out


@dataclass(frozen=True)
class AgentIds:
    """The agents of one run: ``names`` (spec -> the name its episodes are stored under) and
    ``fingerprints`` (name -> :func:`icrsumo.agents.identity.fingerprint`; a guarded row's
    covers its agent and its guard); ``specs``: one spec per name, in the order given (two specs
    of one agent run once); ``guard_names``: guard spec -> the name in its rows; ``on_block``:
    the guarded rows' block policy."""

    names: Mapping[str, str]
    fingerprints: Mapping[str, str]
    specs: tuple[str, ...]
    guard_names: Mapping[str, str] = field(default_factory=dict)
    on_block: str = "keep"

    def config(self) -> dict[str, dict[str, str]]:
        """The ``agents`` entry of OUT/config.json: name -> fingerprint and the spec that rebuilds
        the agent (an agent file's path made absolute); a guarded row also names its ``guard``
        (and a block policy other than keep, ``on_block``)."""
        out = {}
        for spec in self.specs:
            name, shown = self.names[spec], spec
            target, sep, cls = spec.rpartition(":")
            if sep and target.endswith(".py") and not spec.startswith("remote:"):
                shown = f"{Path(target).resolve()}:{cls}"
            shown = display_url(shown)   # a password in a remote: or llm: URL is never stored
            out[name] = {"fingerprint": self.fingerprints[name], "spec": shown}
            policy = {"on_block": self.on_block} if self.on_block != "keep" else {}
            for guard, gname in self.guard_names.items():
                row = guarded_name(name, gname, self.on_block)
                out[row] = {"fingerprint": self.fingerprints[row], "spec": shown, "guard": display_url(guard),
                            **policy}
        return out


def identify_agents(factories: Mapping[str, Callable], replacing: tuple[str, ...] = (),
                    guards: Mapping[str, Callable] | None = None, on_block: str = "keep") -> AgentIds:
    """Names and fingerprints of resolved agents and of their guarded rows (``guards``: guard
    spec -> factory, under block policy ``on_block``); an InputError when two different agents
    (other fingerprints) share a name, when two guards share a name, or when ``replacing`` names
    no agent of the run."""
    from icrsumo.agents.identity import fingerprint, short
    from icrsumo.guards.registry import guard_name

    names: dict[str, str] = {}
    fps: dict[str, str] = {}
    first: dict[str, str] = {}
    for spec, factory in factories.items():
        name = names[spec] = check_name(agent_name(spec, factory), "agent", spec)
        fp = fingerprint(factory)
        if name in fps and fps[name] != fp:
            raise InputError(Field("agents"), spec,
                             f"is named {name!r}, as {first[name]} is, but is another agent "
                             f"(fingerprint {short(fp)}, not {short(fps[name])})",
                             "give one of them another name (the class's name attribute), or evaluate them "
                             f"into separate {Field('out')} folders")
        fps.setdefault(name, fp)
        first.setdefault(name, spec)
    gnames: dict[str, str] = {}
    for gspec, gfactory in (guards or {}).items():
        gname = gnames[gspec] = check_name(guard_name(gspec, gfactory), "guard", gspec)
        other = next((s for s, n in gnames.items() if n == gname and s != gspec), None)
        if split_policy(gname)[1] != "keep":
            raise InputError(Field("guards"), gspec, f"is named {gname!r}, which ends as the rows of a block "
                             f"policy do ({Field('on_block')})", "give the guard another name (the guard "
                             "class's name attribute)")
        if other is not None:
            raise InputError(Field("guards"), gspec, f"is named {gname!r}, as {other} is",
                             "give one of them another name (the guard class's name attribute)")
        gfp = fingerprint(gfactory)
        for name in list(dict.fromkeys(names.values())):
            fps[guarded_name(name, gname, on_block)] = guarded_fingerprint(fps[name], gfp, on_block)
    for name in replacing:
        if name not in fps:
            raise InputError(Field("replace_agents"), name, "is not an agent of this run",
                             f"name one of {', '.join(sorted(fps))}")
    return AgentIds(names, fps, tuple(first.values()), gnames, on_block)


def check_name(name: str, kind: str, spec: str) -> str:
    """``name`` (of an agent or guard, ``kind``, given as ``spec``) when it has at most
    :data:`MAX_NAME` characters: it names the rows, tables and files of its results; an
    InputError before any episode runs otherwise."""
    if len(name) > MAX_NAME:
        raise InputError(kind, short(spec, 60), f"its name {short(name)} is {len(name)} characters long "
                         f"(at most {MAX_NAME})", f"give the {kind} a shorter name (the class's name "
                         f"attribute; a {kind} without one is named by its spec)")
    return name


def check_agents(store_path: Path, ids: AgentIds, replacing: tuple[str, ...]) -> None:
    """An InputError when the store at ``store_path`` (if any) holds episodes of another agent
    under one of ``ids``' names (see :meth:`ResultStore.check_agents`); nothing is written."""
    ResultStore.check(store_path)
    if store_path.exists():
        with ResultStore(store_path, verify=False) as store:
            store.check_agents(ids.fingerprints, replacing)


def claim_agents(store: ResultStore, ids: AgentIds, replacing: tuple[str, ...]) -> None:
    """Claim the run's agents in ``store`` (replacing those in ``replacing``) and say on stderr
    what each replacement deleted (how many stored episodes, of which fingerprint) and which
    agents' stored episodes predate fingerprints (they are taken as the agent's)."""
    from icrsumo.agents.identity import short as short_fp

    doomed = store.replaceable(ids.fingerprints, replacing)
    for name in store.claim_agents(ids.fingerprints, replacing):
        note(f"the stored episodes of {name} were stored before icrsumo kept agent fingerprints; they "
             f"are taken as this agent's ({Field('replace_agents')} {name} runs them again)")
    for name, (n, fps) in doomed.items():
        old = ", ".join(short_fp(fp) if fp else "none (stored before fingerprints)" for fp in fps)
        what = (f"deleted {n} stored episode{'s' * (n != 1)} of the agent of fingerprint {old}" if n else
                "no stored episodes of another agent to delete (replaced already)")
        print(f"icrsumo: replacing {visible(name)} (now {short_fp(ids.fingerprints[name])}): {what}",
              file=sys.stderr)


def run_evaluation(opts: EvalOptions) -> EvalResult:
    """Run (or resume) an evaluation and write its reports. Everything is checked before anything
    is written (options, agents, the out folder's configuration and store, the suite); the run
    owns the out folder while it runs (:class:`icrsumo.core.fsio.FolderLock`)."""
    sink = ProfileSink(opts.workers) if opts.profile is True else None
    opts.check()
    factories = resolve_agents(opts.agents)
    guards = resolve_guards(opts.guards)
    ids = identify_agents(factories, opts.replace_agents, guards, opts.on_block)
    opts = replace(opts, agents=ids.specs)
    with FolderLock(Path(opts.out)):
        result = _run_locked(opts, factories, guards, ids, sink)
    return result if sink is None else replace(result, profile=sink.finish())


def _run_locked(opts: EvalOptions, factories: dict[str, Callable], guards: dict[str, Callable],
                ids: AgentIds, sink: ProfileSink | None = None) -> EvalResult:
    names = ids.names
    out = Path(opts.out)
    check_agents(out / "results.sqlite", ids, opts.replace_agents)
    factories = bind_agents(factories, out)
    bound_guards = bind_guards(guards, out)
    prep = prepare_suite(opts, ids.config())
    written = set(prep.routes)
    planned = plan_jobs(opts, prep.scenarios, prep.instructions, names, ids.guard_names)
    jobs = with_factories([j for j in planned if j.route_id in written], factories, bound_guards)
    with ResultStore(out / "results.sqlite", verify=False) as store:  # checked above
        claim_agents(store, ids, opts.replace_agents)
        check_stored_routes(opts, store, set(names.values()), written, prep.skipped)
        for line in prep.skipped:
            print(f"icrsumo: skipped: {visible(line)}", file=sys.stderr)
        if not written:
            raise no_routes(opts)
        have = store.keys(EpisodeStatus.DONE if opts.retry_crashed else None)
        todo = longest_first([j for j in jobs if j.key not in have])
        with Progress(len(todo), opts.quiet) as progress:
            servers = start_inference(opts, todo, factories)
            try:
                run_queue(route_jobs(todo, servers), opts, store, progress, sink)
            finally:
                progress.close()
                stats = stop_inference(opts, servers)
        keys = {j.key for j in jobs}
        stored = store.records()
        records = [r for r in stored if (r.agent, r.route_id, r.family, r.k, r.seed) in keys]
        summary = write_outputs(opts, out, store, records, prep.scenarios, prep.instructions,
                                not_shown=len(stored) - len(records))
    return EvalResult(stats=summary, out=out, episodes=len(jobs), ran=len(todo), done=summary.episodes.done,
                      crashed=summary.episodes.crashed, inference=stats)


def check_stored_routes(opts: EvalOptions, store: ResultStore, agents: set[str], prepared: set[str],
                        skipped: tuple[str, ...]) -> None:
    """An InputError when the store holds episodes of this evaluation's agents on a route of
    its selection that could not be prepared this time (e.g. its scenario's network is gone):
    a report without them would silently drop stored results."""
    lost: dict[str, int] = {}
    for agent, route, *_ in store.keys():  # noqa: SIM118 - a store, not a dict
        if agent in agents and route not in prepared and (not opts.routes or route in opts.routes):
            lost[route] = lost.get(route, 0) + 1
    if lost:
        route = sorted(lost)[0]
        why = skip_reason(skipped, route) or ""
        raise InputError(store.path, f"route {route}", f"holds {lost[route]} stored episodes, but the route "
                         f"cannot be loaded any more{f' ({why})' if why else ''}"
                         f"{f'; {len(lost) - 1} more such routes' if len(lost) > 1 else ''}",
                         "restore the route's scenario and instructions in the out folder, or rebuild the "
                         "tables from the store alone with icrsumo report OUT")


def check_still_there(store: ResultStore) -> None:
    """An InputError when the store's file (its out folder) is gone: a folder deleted during a
    run fails its remaining episodes for want of their files, which is no agent's crash, and the
    episodes stored meanwhile would go to a file nobody can open."""
    if not store.path.exists():
        raise InputError(store.path.parent, "", "the out folder (or its results store) was deleted while "
                         "the run was going: the episodes stored in it are lost",
                         "run again into a folder that stays")


def run_queue(queue: list[Job], opts: EvalOptions, store: ResultStore, progress: Progress,
              sink: ProfileSink | None = None) -> None:
    """Run ``queue`` on the backend, storing each episode at once; an episode that crashed
    (:data:`RETRIED` kinds) is run again once, then stored as crashed; a timed-out one is stored
    at once. A crashed episode is stored with the log of its last attempt's steps up to the
    crash, where there is one (:class:`~icrsumo.evaluation.execute.Outcome`). ``sink`` collects
    the jobs' timings (``opts.profile``)."""
    attempts: dict[tuple, int] = {}
    while queue:
        retry = []
        if sink is not None:
            sink.round_start()
        for job, outcome in run_jobs(queue, opts):
            if sink is not None:
                sink.add(outcome.timing)
            check_still_there(store)
            n = attempts[job.key] = attempts.get(job.key, 0) + 1
            if outcome.status is OutcomeStatus.DONE:
                store.put(replace(outcome.record, attempts=n), outcome.log_json)
                progress.tick()
            elif n < MAX_ATTEMPTS and outcome.error_kind in RETRIED:
                retry.append(job)
            else:
                rec = outcome.record or EpisodeRecord(job.agent, job.route_id, job.family, job.k, job.seed,
                                                      status=EpisodeStatus.CRASHED)
                store.put(replace(rec, attempts=n, message=outcome.message[:MAX_MESSAGE]),
                          outcome.log_json or None)
                progress.tick()
        if sink is not None:
            sink.round_end()
        queue = retry


def report_only(out: Path, quiet: bool = False, scoring: str | None = None) -> Summary:
    """Rebuild summary, tables and figures of an evaluation folder from its store (no SUMO);
    returns the summary. With ``scoring`` (a name of :data:`icrsumo.scoring.SCORINGS`) every
    finished episode is rescored from its stored log by those rules (the store is left as it
    is; the summary names the scoring); without, the stored scores are reported.
    The report owns the folder while it writes (:class:`icrsumo.core.fsio.FolderLock`): a run still
    storing episodes there is an InputError, never a summary of half its episodes. The store is
    only read."""
    out = Path(out)
    read_config(out)  # an InputError for a folder that is no evaluation's, before the lock
    if scoring is not None and scoring not in SCORINGS:
        raise InputError(Field("scoring"), scoring, "unknown scoring", f"use {', '.join(scoring_names())}")
    with FolderLock(out, busy_fix="wait for it to end (an evaluation writes its reports when it ends), "
                    "then report again"):
        return _report_locked(out, quiet, scoring)


def _report_locked(out: Path, quiet: bool, scoring: str | None) -> Summary:
    cfg_path = out / "config.json"
    cfg = read_config(out)
    stored_scoring = cfg.get("scoring")
    with ResultStore(out / "results.sqlite", readonly=True) as store:
        records = store.records()
        inexact = 0
        if scoring is not None:
            records, inexact = rescore(store, records, scoring)
        elif stored_scoring is None:
            raise InputError(cfg_path, "scoring", "its episodes were scored before icrsumo scored by the "
                             "leaderboard's own rules", f"run them again into another {Field('out')} folder")
        families = tuple(f for f in ALL_FAMILIES if any(r.family == f for r in records))
        agents = tuple(sorted({r.agent for r in records}))
        # episodes the tables cannot hold (an attack's searches and transfers): counted and named
        others = sorted({str(r.family) for r in records
                         if r.family != "baseline" and r.family not in families})
        opts = EvalOptions(out=out, suite=cfg["suite"], agents=agents or (DEFAULT_AGENT,),
                           families=families or FAMILIES, k=int(cfg["k"]), seed=int(cfg["seed"]),
                           traffic=str(cfg.get("traffic", "normal")), quiet=quiet,
                           scoring=scoring or stored_scoring)
        return write_outputs(opts, out, store, records, out / "scenarios" if (out / "scenarios").is_dir()
                             else Path(cfg["suite"]), out / "instructions", rescored_short=inexact,
                             not_shown=sum(str(r.family) in others for r in records),
                             not_shown_why=_not_in_tables(others))


def _not_in_tables(families: list[str]) -> str:
    """Why stored episodes of ``families`` (not the protocol's) are not in the tables."""
    if not families:
        return ""
    attack = {"attack", "transfer"} & set(families)
    where = " (the attack's own report: attack.json, attack.md)" if attack else ""
    return f"they are of the families {', '.join(families)}, which the ICR tables do not hold{where}"


def rescore(store: ResultStore, records: list[EpisodeRecord],
            scoring: str) -> tuple[list[EpisodeRecord], int]:
    """``records`` with every finished episode scored again from its stored log under
    ``scoring`` (:func:`icrsumo.scoring.score_episode`), and how many of them ended, under the
    rules they were recorded with, before ``scoring``'s rules would have ended them (those are
    scored on what was recorded; a fresh run with ``scoring`` would have simulated longer).
    Crashed episodes stay as they are. An InputError names a finished episode whose log is
    missing or cannot be read (a rescored report never drops one silently)."""
    from icrsumo.scoring import get_scoring

    from .execute import with_scores

    out, short = [], 0
    for r in records:
        if r.status == EpisodeStatus.DONE:
            log = store.episode_log(r.agent, r.route_id, r.family, r.k, r.seed)
            if log is None:
                raise InputError(store.path, f"episode {r.agent}/{r.route_id}/{r.family}/{r.k}",
                                 "has no stored log to rescore",
                                 f"run the evaluation again into another {Field('out')} folder")
            r = with_scores(r, score_episode(log, scoring))
            short += not get_scoring(scoring).ended_by(log)[1]
        out.append(r)
    return out, short
