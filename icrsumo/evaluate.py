"""``icrsumo evaluate``: the paired ICR protocol over routes x instruction sets x agents.

For every agent and route: the baseline sequence and K variants of each selected family, all
on the same scenario, seed and traffic. The out folder holds everything (reused on rerun):

    OUT/config.json         suite, seed, k, traffic: a rerun with another one is refused
    OUT/scenarios/          convert-routes output
    OUT/instructions/       generate output
    OUT/results.sqlite      one row per finished episode (committed at once): resumable
    OUT/summary.json, results.{md,csv,tex}, episodes.csv, figures/, leaderboard/

Episodes run in worker processes (one SUMO each: ``--workers``, default the number of cores)
or on Ray (``--backend ray``). Every episode is deterministic, so results do not depend on the
backend or the worker count. An episode that raises is retried once, then stored as crashed.

Hung agents: every ``reset`` / ``act`` call has ``agent_timeout`` seconds (``--agent-timeout``,
default 60). The local backend's parent process watches each worker's current agent call and
kills and replaces a worker whose call overruns (this stops any hang, also in C code); Ray
workers interrupt the call with SIGALRM (hangs in Python code). The episode is stored as
crashed with "agent did not answer within N s", without a retry, and the run goes on.
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing
import multiprocessing.connection
import os
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

from .agents.base import AgentTimeout
from .agents.registry import DEFAULT_AGENT, agent_factory, agent_name
from .convert import ConvertOptions, convert_routes, safe_name
from .errors import InputError
from .fsio import dumps_json, write_atomic
from .instructions.families import FAMILIES
from .instructions.generate import GenerateOptions, generate
from .resources import bundled_suites
from .scenario import find_scenarios, read_scenario
from .store import ResultStore
from .types import EpisodeRecord

BACKENDS = ("local", "ray")
#: seconds an agent's reset / act call may take by default (--agent-timeout)
AGENT_TIMEOUT = 60.0


@dataclass(frozen=True)
class EvalOptions:
    """One evaluation. ``routes``: a subset of route ids (None: all). ``agent_timeout``: s an
    agent's reset / act call may take (None: no limit, and ``workers=1`` runs in-process)."""

    out: Path
    suite: str = "tiny"
    agents: tuple[str, ...] = (DEFAULT_AGENT,)
    families: tuple[str, ...] = FAMILIES
    k: int = 8
    seed: int = 2026
    routes: tuple[str, ...] | None = None
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    backend: str = "local"
    address: str | None = None
    traffic: str = "normal"
    quiet: bool = False
    rollout_route: str | None = None
    agent_timeout: float | None = AGENT_TIMEOUT
    #: device of one batched inference process per non-privileged agent (None: every worker
    #: runs its own agent), e.g. "cuda"; ``max_batch``: observations per forward pass
    batch_inference: str | None = None
    max_batch: int = 32
    #: inference processes per agent with ``batch_inference`` (each worker uses one)
    inference_processes: int = 1

    def check(self) -> None:
        bad = [f for f in self.families if f not in FAMILIES]
        if bad or not self.families:
            raise InputError("--family", bad[0] if bad else "", "unknown family",
                             f"use {', '.join(FAMILIES)}")
        if self.backend not in BACKENDS:
            raise InputError("--backend", self.backend, "unknown backend", "use local or ray")
        if not 1 <= self.k <= 64:
            raise InputError("--k", str(self.k), "out of range", "use 1 to 64 (default 8)")
        if self.workers < 1:
            raise InputError("--workers", str(self.workers), "must be at least 1", "give a positive count")
        if self.agent_timeout is not None and not self.agent_timeout > 0:
            raise InputError("--agent-timeout", str(self.agent_timeout), "must be positive",
                             "give seconds per agent call (0 on the command line: no limit)")
        for spec in self.agents:
            agent_factory(spec)
        if self.batch_inference is not None:
            if self.backend != "local":
                raise InputError("--batch-inference", self.batch_inference, "works with the local backend "
                                 "only (its workers reach the inference process through a Unix socket)",
                                 "use --backend local")
            if self.max_batch < 1:
                raise InputError("--max-batch", str(self.max_batch), "must be at least 1",
                                 "give a positive count")
            if self.inference_processes < 1:
                raise InputError("--inference-processes", str(self.inference_processes),
                                 "must be at least 1", "give a positive count")
        p = Path(self.suite)
        if self.suite not in bundled_suites() and not p.is_file() and not (p / "index.json").is_file():
            raise InputError("--suite", self.suite, "unknown suite",
                             "use tiny, short, long, a route XML file or a convert-routes folder")


@dataclass(frozen=True)
class Job:
    """One episode to run: its store key and the files it needs."""

    agent_spec: str
    agent: str
    route_id: str
    family: str
    k: int
    seed: int
    scenario: str
    instructions: str
    #: s per agent call, enforced in the worker with SIGALRM where no parent watches (Ray)
    timeout: float | None = None

    @property
    def key(self) -> tuple[str, str, str, int, int]:
        return (self.agent, self.route_id, self.family, self.k, self.seed)


# --------------------------------------------------------------------------- workers
_AGENTS: dict[str, Callable] = {}
#: in a local pool worker: shared double, time.monotonic() when the current agent call began
#: (0.0: none); the parent kills the worker when a call overruns the timeout
_WATCH = None


class _Watched:
    """An agent whose ``reset`` / ``act`` calls are timed: marked in the worker's watch slot (the
    parent enforces the timeout), else interrupted by SIGALRM after ``timeout`` s (main thread
    only). ``name`` and ``privileged`` are the agent's, so the episode is the same."""

    def __init__(self, agent, slot, timeout: float | None) -> None:
        self._agent, self._slot, self._timeout = agent, slot, timeout
        self.name = getattr(agent, "name", type(agent).__name__)
        self.privileged = getattr(agent, "privileged", False)
        self._alarm = (slot is None and timeout is not None and hasattr(signal, "SIGALRM")
                       and threading.current_thread() is threading.main_thread())

    def _call(self, fn, arg):
        if self._slot is not None:
            self._slot.value = time.monotonic()
            try:
                return fn(arg)
            finally:
                self._slot.value = 0.0
        if not self._alarm:
            return fn(arg)
        timeout = self._timeout

        def expired(signum, frame):
            raise AgentTimeout(f"agent did not answer within {timeout:g} s")

        old = signal.signal(signal.SIGALRM, expired)
        signal.setitimer(signal.ITIMER_REAL, timeout)
        try:
            return fn(arg)
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
            signal.signal(signal.SIGALRM, old)

    def __getattr__(self, attr: str):  # anything else is the agent's own
        return getattr(self.__dict__["_agent"], attr)

    def reset(self, info):
        return self._call(self._agent.reset, info)

    def act(self, obs):
        return self._call(self._agent.act, obs)

    def close(self) -> None:
        """The agent's optional ``close()`` (best effort: its errors are ignored)."""
        if callable(getattr(self._agent, "close", None)):
            with contextlib.suppress(Exception):
                self._agent.close()


def run_job(job: Job) -> tuple[EpisodeRecord | None, str, str]:
    """Run one episode (in a worker): (record, log JSON, "") or (None, "", error message)."""
    from .instructions.store import read_instruction_sets
    from .logs import dumps_log
    from .metrics import score_episode
    from .runner import run_episode

    try:
        factory = _AGENTS.get(job.agent_spec)
        if factory is None:
            factory = _AGENTS[job.agent_spec] = agent_factory(job.agent_spec)
        sc = read_scenario(Path(job.scenario))
        sets = [s for s in read_instruction_sets(Path(job.instructions))
                if s.family == job.family and s.k == job.k]
        agent = _Watched(factory(), _WATCH, job.timeout)
        try:
            log = run_episode(sc, sets[0], agent)
        finally:
            agent.close()  # the optional close() hook: e.g. a remote agent ends its session
        r = score_episode(log)
        rec = EpisodeRecord(
            agent=job.agent, route_id=job.route_id, family=job.family, k=job.k, seed=job.seed,
            status="done", ds=r.ds, rc=r.rc, is_=r.is_, termination=r.termination,
            termination_class=r.termination_class.value,
            infractions=tuple((i.kind, i.factor) for i in r.infractions),
            length=round(sc.length, 2), duration=r.duration, message=log.message,
        )
        return rec, dumps_log(log), ""
    except Exception as err:  # an agent or the simulator failed: the caller retries / records
        tb = traceback.extract_tb(err.__traceback__)
        where = f" at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno}" if tb else ""
        return None, "", f"{type(err).__name__}: {err}{where}"


# --------------------------------------------------------------------------- backends
def _worker_main(conn, slot) -> None:
    """A local pool worker: run the jobs it is sent, one at a time, until it is sent None."""
    global _WATCH
    _WATCH = slot
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError):
            return
        if job is None:
            return
        conn.send(run_job(job))


class _Worker:
    """One worker process, its pipe and its watch slot (see :data:`_WATCH`)."""

    def __init__(self, ctx) -> None:
        self.slot = ctx.Value("d", 0.0, lock=False)
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker_main, args=(child, self.slot), daemon=True)
        self.proc.start()
        child.close()
        self.job: Job | None = None

    def send(self, job: Job) -> None:
        self.job = job
        self.slot.value = 0.0
        self.conn.send(job)

    def stop(self, kill: bool = False) -> None:
        if not kill:
            try:
                self.conn.send(None)
                self.proc.join(timeout=10)
            except (OSError, ValueError):
                pass
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()
        self.conn.close()


def _local(jobs: list[Job], workers: int, timeout: float | None = None) -> Iterator[tuple[Job, tuple]]:
    """Run ``jobs`` in ``workers`` processes; a worker whose agent call overruns ``timeout`` s
    (or that dies) is replaced and its episode reported as failed. ``workers == 1`` without a
    timeout runs in this process."""
    if workers == 1 and timeout is None:
        for job in jobs:
            yield job, run_job(job)
        return
    if not jobs:
        return
    ctx = multiprocessing.get_context()
    it = iter(jobs)
    busy: dict = {}
    pool: list[_Worker] = []

    def feed(w: _Worker) -> None:
        job = next(it, None)
        if job is not None:
            w.send(job)
            busy[w.conn] = w

    try:
        for _ in range(min(workers, len(jobs))):
            pool.append(_Worker(ctx))
            feed(pool[-1])
        while busy:
            for conn in multiprocessing.connection.wait(list(busy), timeout=0.2):
                w = busy.pop(conn)
                job, w.job = w.job, None
                try:
                    result = conn.recv()
                except (EOFError, OSError):
                    w.proc.join(timeout=5)
                    result = (None, "", f"WorkerDied: the worker process died (exit code {w.proc.exitcode}) "
                                        f"while running this episode")
                    w.stop(kill=True)
                    pool[pool.index(w)] = w = _Worker(ctx)
                yield job, result
                feed(w)
            if timeout is not None:
                now = time.monotonic()
                for conn, w in list(busy.items()):
                    began = w.slot.value
                    if began and now - began > timeout:
                        busy.pop(conn)
                        job = w.job
                        w.stop(kill=True)
                        pool[pool.index(w)] = w = _Worker(ctx)
                        yield job, (None, "", f"AgentTimeout: agent did not answer within {timeout:g} s "
                                              f"(its worker process was stopped)")
                        feed(w)
    finally:
        for w in pool:
            w.stop(kill=w.conn in busy)


def _ray(jobs: list[Job], workers: int, address: str | None) -> Iterator[tuple[Job, tuple]]:
    try:
        import ray
    except ImportError:
        raise InputError("--backend ray", "", "Ray is not installed",
                         "pip install 'icrsumo[ray]'") from None
    started = not ray.is_initialized()
    if started:
        if address:
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
        else:
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    try:
        remote = ray.remote(num_cpus=1, max_calls=0)(run_job)
        refs = {}
        it = iter(jobs)
        for job in it:
            refs[remote.remote(job)] = job
            if len(refs) >= 2 * workers:
                break
        while refs:
            ready, _ = ray.wait(list(refs), num_returns=1)
            for ref in ready:
                job = refs.pop(ref)
                yield job, ray.get(ref)
                nxt = next(it, None)
                if nxt is not None:
                    refs[remote.remote(nxt)] = nxt
    finally:
        if started:
            ray.shutdown()


class _Progress:
    """Episodes done, episodes per second and ETA on stderr (one line per 10 % when not a TTY)."""

    def __init__(self, total: int, quiet: bool) -> None:
        self.total, self.quiet, self.done, self.t0 = total, quiet, 0, time.perf_counter()
        self.tty = sys.stderr.isatty()
        self._last_decile = -1

    def tick(self) -> None:
        self.done += 1
        if self.quiet or self.total == 0:
            return
        dt = max(time.perf_counter() - self.t0, 1e-9)
        rate = self.done / dt
        eta = (self.total - self.done) / rate if rate > 0 else 0.0
        line = (f"[{self.done:>5}/{self.total}] {rate:5.2f} episodes/s  "
                f"ETA {int(eta // 60):02d}:{int(eta % 60):02d}")
        if self.tty:
            print("\r" + line, end="" if self.done < self.total else "\n", file=sys.stderr, flush=True)
        elif self.done * 10 // self.total != self._last_decile:
            self._last_decile = self.done * 10 // self.total
            print(line, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- protocol
def _resolve_suite(suite: str, out: Path, opts: EvalOptions) -> Path:
    """The folder of converted scenarios for ``suite`` (converting into OUT/scenarios)."""
    p = Path(suite)
    if p.is_dir() and (p / "index.json").is_file():
        return p
    bundled = bundled_suites()
    routes = bundled.get(suite, p)
    target = out / "scenarios"
    report = convert_routes(routes, target, ConvertOptions(traffic=opts.traffic, workers=opts.workers))
    for line in report.failures:
        print(f"icrsumo: skipped: {line}", file=sys.stderr)
    return target


def _check_config(out: Path, opts: EvalOptions) -> dict:
    config = {"suite": opts.suite, "seed": opts.seed, "k": opts.k, "traffic": opts.traffic}
    path = out / "config.json"
    if path.is_file():
        old = json.loads(path.read_text(encoding="utf-8"))
        diff = [k for k in config if old.get(k) != config[k]]
        if diff:
            shown = ", ".join(f"{k}={old.get(k)!r} (now {config[k]!r})" for k in diff)
            raise InputError(out, "config.json", f"holds results of a different configuration: {shown}",
                             "use another --out folder, or the same options")
    return config


def plan_jobs(opts: EvalOptions, scenarios: Path, instr_dir: Path) -> list[Job]:
    """Every episode of the protocol, in a fixed order (agent, route, family, k)."""
    scs = [(d, read_scenario(d)) for d in find_scenarios(scenarios)]
    if opts.routes:
        missing = sorted(set(opts.routes) - {sc.route_id for _, sc in scs})
        if missing:
            raise InputError("--routes", missing[0], "no such route in the suite", "check the route ids")
        scs = [(d, sc) for d, sc in scs if sc.route_id in set(opts.routes)]
    sets = [("baseline", 0)] + [(f, k) for f in opts.families for k in range(opts.k)]
    jobs = []
    for spec in opts.agents:
        name = agent_name(spec, agent_factory(spec))
        for d, sc in scs:
            instr = str(instr_dir / f"{safe_name(sc.route_id)}.json")
            for fam, k in sets:
                jobs.append(Job(spec, name, sc.route_id, fam, k, opts.seed, str(d), instr,
                                timeout=opts.agent_timeout if opts.backend == "ray" else None))
    return jobs


def evaluate(opts: EvalOptions) -> dict:
    """Run (or resume) an evaluation and write its reports; returns the summary."""
    opts.check()
    out = Path(opts.out)
    config = _check_config(out, opts)
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(out / "config.json", dumps_json(config))
    scenarios = _resolve_suite(opts.suite, out, opts)
    instr_dir = out / "instructions"
    written, failures = generate(scenarios, instr_dir, GenerateOptions(
        families=FAMILIES, k=opts.k, seed=opts.seed, workers=1))
    for line in failures:
        print(f"icrsumo: skipped: {line}", file=sys.stderr)
    jobs = [j for j in plan_jobs(opts, scenarios, instr_dir) if j.route_id in set(written)]
    with ResultStore(out / "results.sqlite") as store:
        have = store.keys()
        todo = [j for j in jobs if j.key not in have]
        progress = _Progress(len(todo), opts.quiet)
        attempts: dict[tuple, int] = {}
        servers = _start_batch_servers(opts, todo)
        queue = [replace(j, agent_spec=servers[j.agent_spec].worker_spec) if j.agent_spec in servers else j
                 for j in todo]
        try:
            _run_queue(queue, opts, store, progress, attempts)
        finally:
            for server in servers.values():
                s = server.stop()
                if s and not opts.quiet:
                    print(f"icrsumo: batched inference of {server.name} on {opts.batch_inference} "
                          f"({s['processes']} process{'es' if s['processes'] > 1 else ''}): "
                          f"{s['acts']} actions in {s['batches']} forward passes (mean batch "
                          f"{s['acts'] / max(s['batches'], 1):.1f}, largest {s['largest_batch']})",
                          file=sys.stderr)
        keys = {j.key for j in jobs}
        records = [r for r in store.records() if (r.agent, r.route_id, r.family, r.k, r.seed) in keys]
        summary = _report(opts, out, store, records, scenarios, instr_dir)
    return summary


def _start_batch_servers(opts: EvalOptions, todo: list[Job]) -> dict:
    """The batched inference processes of each non-privileged agent spec of ``todo`` (spec ->
    :class:`icrsumo.agents.batched.ServerGroup`), when ``opts.batch_inference`` is set."""
    if opts.batch_inference is None or not todo:
        return {}
    from .agents.batched import start_group

    servers: dict = {}
    try:
        for spec in dict.fromkeys(j.agent_spec for j in todo):
            if not getattr(agent_factory(spec), "privileged", False):
                servers[spec] = start_group(spec, opts.batch_inference, opts.max_batch,
                                            opts.inference_processes)
    except BaseException:
        for server in servers.values():
            server.stop()
        raise
    return servers


def _run_queue(queue: list[Job], opts: EvalOptions, store: ResultStore, progress: _Progress,
               attempts: dict) -> None:
    """Run ``queue`` on the backend, storing each episode at once; a failed episode is retried
    once (a hang is not), then stored as crashed."""
    while queue:
        retry = []
        stream = _ray(queue, opts.workers, opts.address) if opts.backend == "ray" \
            else _local(queue, opts.workers, opts.agent_timeout)
        for job, (rec, log_json, err) in stream:
            n = attempts[job.key] = attempts.get(job.key, 0) + 1
            if rec is not None:
                store.put(EpisodeRecord(**{**rec.__dict__, "attempts": n}), log_json)
                progress.tick()
            elif n < 2 and not err.startswith(f"{AgentTimeout.__name__}:"):  # a hang is not retried
                retry.append(job)
            else:
                store.put(EpisodeRecord(job.agent, job.route_id, job.family, job.k, job.seed,
                                        status="crashed", attempts=n, message=err[:2000]))
                progress.tick()
        queue = retry


def report_only(out: Path, quiet: bool = False) -> dict:
    """Rebuild summary, tables and figures of an evaluation folder from its store (no SUMO)."""
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
        return _report(opts, out, store, records, out / "scenarios" if (out / "scenarios").is_dir()
                       else Path(cfg["suite"]), out / "instructions")


def _report(opts: EvalOptions, out: Path, store: ResultStore, records: list[EpisodeRecord],
            scenarios: Path, instr_dir: Path) -> dict:
    from .aggregate import summarize
    from .report import write_report

    families = tuple(f for f in FAMILIES if f in opts.families)  # canonical order
    summary = summarize(records, suite=opts.suite, seed=opts.seed, k=opts.k, families=families)
    table = write_report(summary, records, out)
    _rollout_figure(opts, out, store, records, scenarios, instr_dir)
    if not opts.quiet:
        print(table)
    return summary


def _rollout_figure(opts: EvalOptions, out: Path, store: ResultStore, records: list[EpisodeRecord],
                    scenarios: Path, instr_dir: Path) -> None:
    """Paired rollout figure: baseline vs k = 0 of each family for one route and agent."""
    from .instructions.store import read_instruction_sets
    from .logs import loads_log
    from .networks import load_net
    from .report import paired_rollout

    done = [r for r in records if r.status == "done" and r.family == "baseline"]
    if not done:
        return
    route = opts.rollout_route or done[0].route_id
    agent = done[0].agent
    base_json = store.log(agent, route, "baseline", 0, opts.seed)
    if base_json is None:
        return
    sets = {(s.family, s.k): s for s in read_instruction_sets(instr_dir / f"{safe_name(route)}.json")}
    variants = []
    for fam in opts.families:
        lj = store.log(agent, route, fam, 0, opts.seed)
        if lj is not None and (fam, 0) in sets:
            variants.append((f"{fam} k=0", loads_log(lj), sets[(fam, 0)].instructions[0].rendered()))
    sc_dir = next((d for d in find_scenarios(scenarios) if read_scenario(d).route_id == route), None)
    if sc_dir is None:
        return
    net = load_net(read_scenario(sc_dir).net)
    fig = out / "figures" / f"rollout_{safe_name(route)}.png"
    fig.parent.mkdir(parents=True, exist_ok=True)
    paired_rollout(net, loads_log(base_json), variants, sets[("baseline", 0)].instructions[0].rendered(),
                   fig, title=f"{agent} on {route}")
