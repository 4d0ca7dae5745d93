"""Running one episode job in a worker: the agent's calls guarded by a
:class:`~icrsumo.agents.hosting.watch.CallWatch`, the episode scored, and a typed :class:`Outcome`
returned (never an exception): done with its record and log, crashed with an
:class:`~icrsumo.core.vocab.ErrorKind` and a one-line message, or timed out (a crash or timeout
inside the episode's loop keeps the log of its steps up to it)."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Hashable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from icrsumo.agents.base import Agent, AgentTimeout
from icrsumo.agents.hosting.watch import CallWatch, Unwatched
from icrsumo.agents.registry import agent_factory
from icrsumo.core.errors import Interrupted, describe
from icrsumo.core.types import EpisodeLog, EpisodeRecord, InstructionSet
from icrsumo.core.vocab import EpisodeStatus, ErrorKind, OutcomeStatus, Phase, Verdict
from icrsumo.guards.base import split_policy, split_row
from icrsumo.scoring.leaderboard import with_scores
from icrsumo.sim.callbacks import PhaseClock
from icrsumo.world.scenario import Scenario

from .plan import Job
from .profile import JobTiming


@dataclass(frozen=True)
class Outcome:
    """What running one job gave. ``status`` done: ``record`` (attempts 1) and ``log_json``;
    crashed or timed_out: ``error_kind`` and ``message`` (one line, e.g.
    ``RuntimeError: agent exploded at my_agent.py:35``) and, when the episode had recorded
    steps before the agent (or its guard) raised or timed out, ``log_json``: its log up to the
    last completed step (termination agent_error), with ``record``: the crashed record to
    store beside it (status crashed, no scores, the route's ``length``). ``timing``: the job's
    phases when its job asked for a profile (``Job.profile``; never stored)."""

    status: OutcomeStatus
    record: EpisodeRecord | None = None
    log_json: str = ""
    error_kind: ErrorKind | None = None
    message: str = ""
    timing: JobTiming | None = None

    @classmethod
    def finished(cls, record: EpisodeRecord, log_json: str) -> Outcome:
        return cls(OutcomeStatus.DONE, record, log_json)

    @classmethod
    def failure(cls, kind: ErrorKind, message: str) -> Outcome:
        """A failed run: timed out for :attr:`ErrorKind.AGENT_TIMEOUT`, else crashed."""
        status = OutcomeStatus.TIMED_OUT if kind is ErrorKind.AGENT_TIMEOUT else OutcomeStatus.CRASHED
        return cls(status, error_kind=kind, message=message)

    @classmethod
    def of_error(cls, err: BaseException, record: EpisodeRecord | None = None, log_json: str = "") -> Outcome:
        """The outcome of an exception raised while running the episode (with the crashed
        ``record`` and the partial log it is stored with, where there is one)."""
        kind = ErrorKind.AGENT_TIMEOUT if isinstance(err, AgentTimeout) else ErrorKind.ERROR
        return replace(cls.failure(kind, describe(err)), record=record, log_json=log_json)


class WatchedAgent:
    """An agent whose ``reset`` / ``act`` calls run under ``watch``. ``name``, ``privileged``
    and ``needs_route`` are the agent's (so the episode is the same); anything else is read
    from the agent."""

    def __init__(self, agent: Agent, watch: CallWatch) -> None:
        self._agent, self._watch = agent, watch
        self.name = getattr(agent, "name", type(agent).__name__)
        self.privileged = getattr(agent, "privileged", False)
        self.needs_route = getattr(agent, "needs_route", False)

    def __getattr__(self, attr: str) -> Any:  # anything else is the agent's own
        return getattr(self.__dict__["_agent"], attr)

    def reset(self, info):
        return self._watch.call(self._agent.reset, info)

    def act(self, obs):
        return self._watch.call(self._agent.act, obs)

    def close(self) -> None:
        """The agent's optional ``close()`` (best effort: its errors are ignored)."""
        if callable(getattr(self._agent, "close", None)):
            with contextlib.suppress(Exception, SystemExit):
                self._agent.close()


class WatchedGuard:
    """An instruction guard whose ``reset`` / ``check`` calls run under ``watch``, as the
    agent's do (a guard that hangs stops its episode as a hung agent does: stored as crashed,
    "guard NAME did not answer within N s"); ``name`` and ``needs_plan`` are the guard's.
    ``row_name``: the guard's name in its rows (what a timeout names)."""

    def __init__(self, guard: object, watch: CallWatch, row_name: str) -> None:
        self._guard, self._watch = guard, watch
        self.name = str(getattr(guard, "name", type(guard).__name__))
        self.needs_plan = bool(getattr(guard, "needs_plan", False))
        self._who = f"guard {row_name}"

    def __getattr__(self, attr: str) -> Any:  # anything else is the guard's own
        return getattr(self.__dict__["_guard"], attr)

    def reset(self, info):
        return self._watch.call(self._guard.reset, info, who=self._who)

    def check(self, text, context):
        return self._watch.call(lambda args: self._guard.check(*args), (text, context), who=self._who)


def row_guard(job: Job) -> str:
    """The name of ``job``'s guard in its row (``AGENT+guard:NAME``, without a block policy's
    ``+navigator``; "" for none)."""
    parts = split_row(job.agent) if job.guard else None
    return split_policy(parts[1])[0] if parts else job.guard


class EpisodeWorker:
    """Runs jobs one at a time in one process, with its agents' calls under ``watch``. Keeps
    the agent factory of each spec (or each job factory) it has met, so user code is imported
    and remote agents are asked for their name once per process, and each scenario and
    instruction file it has read (a route's 33 sequences are 33 jobs); :meth:`close` closes the
    factories that hold connections."""

    def __init__(self, watch: CallWatch | None = None) -> None:
        self.watch: CallWatch = watch if watch is not None else Unwatched()
        self.factories: dict[Hashable, Callable[[], Agent]] = {}
        self.guards: dict[Hashable, Callable[[], object]] = {}
        self._scenarios: dict[str, Scenario] = {}
        self._sets: dict[str, dict[tuple[str, int], InstructionSet]] = {}

    def _inputs(self, job: Job) -> tuple[Scenario, InstructionSet, InstructionSet | None]:
        """The job's scenario, instruction sequence and its route's baseline sequence (each file
        read once per worker)."""
        from icrsumo.instructions.store import read_instruction_sets
        from icrsumo.world.scenario import read_scenario

        sc = self._scenarios.get(job.scenario)
        if sc is None:
            sc = self._scenarios[job.scenario] = read_scenario(Path(job.scenario))
        sets = self._sets.get(job.instructions)
        if sets is None:
            sets = self._sets[job.instructions] = {
                (s.family, s.k): s for s in read_instruction_sets(Path(job.instructions))}
        return sc, sets[(job.family, job.k)], sets.get(("baseline", 0))

    def factory(self, job: Job) -> Callable[[], Agent]:
        ref: Hashable = job.factory if job.factory is not None else (job.agent_spec, job.device)
        factory = self.factories.get(ref)
        if factory is None:
            factory = job.factory if job.factory is not None else agent_factory(job.agent_spec, job.device)
            self.factories[ref] = factory
        return factory

    def guard(self, job: Job) -> object | None:
        """A fresh guard for ``job`` (None without one), its calls under the worker's watch;
        its factory is kept per spec."""
        if not job.guard:
            return None
        ref: Hashable = job.guard_factory if job.guard_factory is not None else job.guard
        factory = self.guards.get(ref)
        if factory is None:
            from icrsumo.guards.registry import guard_factory

            factory = self.guards[ref] = job.guard_factory or guard_factory(job.guard)
        return WatchedGuard(factory(), self.watch, row_guard(job))

    def run(self, job: Job) -> Outcome:
        """Run one episode and score it; every failure becomes an Outcome. With
        ``job.profile`` the outcome carries the job's :class:`JobTiming`."""
        if not job.profile:
            return self._run(job, None)
        clock = PhaseClock()
        outcome = self._run(job, clock)
        clock.lap(Phase.LOGGING)
        rec = outcome.record
        return replace(outcome, timing=JobTiming(
            dict(clock.phases), clock.start, clock.last, os.getpid(), clock.steps,
            rec.duration if rec is not None else 0.0, job.scenario))

    def _run(self, job: Job, clock: PhaseClock | None) -> Outcome:
        from icrsumo.results.logs import ask_counts, dumps_log, loads_log
        from icrsumo.scoring import score_episode
        from icrsumo.sim.episode import RunOptions, drive_episode

        lap = clock.lap if clock is not None else _no_lap
        try:
            factory = self.factory(job)
            lap(Phase.AGENT_LOAD)
            sc, iset, baseline = self._inputs(job)
            guard = self.guard(job)
            lap(Phase.EPISODE_SETUP)
            agent = WatchedAgent(factory(), self.watch)
            lap(Phase.AGENT_LOAD)
            try:
                log, error = drive_episode(sc, iset, agent, RunOptions(
                    scoring=job.scoring, asking=job.asking, on_block=job.on_block),
                    guard=guard, baseline=baseline, clock=clock)
            finally:
                agent.close()  # the optional close() hook: e.g. a remote agent ends its session
            if clock is not None:
                clock.steps = len(log.t)
            if error is not None:  # the agent or its guard raised: the log of the steps up to it
                return Outcome.of_error(error, *partial_crash(job, sc.length, log))
            text = dumps_log(log)
            lap(Phase.LOGGING)
            r = score_episode(loads_log(text), job.scoring)  # the stored log: a rescore gives the same
            lap(Phase.SCORING)
            asks, answered = ask_counts(log)
            rec = with_scores(EpisodeRecord(
                agent=job.agent, route_id=job.route_id, family=job.family, k=job.k, seed=job.seed,
                status=EpisodeStatus.DONE, length=round(sc.length, 2), message=log.message,
                model_calls=len(log.model_calls),
                invalid_answers=sum(not c.valid for c in log.model_calls),
                asks=asks, asks_answered=answered, **guard_counts(log, iset)), r)
            return Outcome.finished(rec, text)
        except Interrupted:  # the user's Ctrl-C (in-process runs): stop the evaluation
            raise
        except BaseException as err:  # noqa: BLE001 - any failure of the agent or the simulator
            # (agent code calling sys.exit, raising KeyboardInterrupt or its own BaseException
            # included): the caller retries / records
            return Outcome.of_error(err)

    def close(self) -> None:
        """Close the factories that hold connections: those whose type has a ``close`` method
        (best effort)."""
        for factory in self.factories.values():
            if callable(getattr(type(factory), "close", None)):
                with contextlib.suppress(Exception):
                    factory.close()
        self.factories.clear()


def partial_crash(job: Job, length: float, log: EpisodeLog) -> tuple[EpisodeRecord | None, str]:
    """The crashed record of ``job`` (no scores; the route's ``length``, m) and the JSON text of
    ``log``, the episode's steps up to the crash; (None, "") when it recorded no step or cannot
    be written (the crash's own message is what the outcome keeps)."""
    from icrsumo.results.logs import dumps_log

    try:
        text = dumps_log(log) if log.t else ""
    except (ValueError, TypeError):
        text = ""
    if not text:
        return None, ""
    rec = EpisodeRecord(agent=job.agent, route_id=job.route_id, family=job.family, k=job.k, seed=job.seed,
                        status=EpisodeStatus.CRASHED, length=round(length, 2), message=log.message)
    return rec, text


def _no_lap(phase: str) -> None:
    """A lap of no clock (a job without a profile)."""


def guard_counts(log: EpisodeLog, iset: InstructionSet) -> dict[str, int]:
    """``guard_checked`` / ``guard_blocked`` / ``guard_repaired`` of an episode: the guard's
    decisions on instructions whose text is not empty and that the family did not keep
    unchanged (a repaired instruction is blocked too: it was not shown as written)."""
    counted = {i.id for i in iset.instructions if i.text.strip() and i.template != "keep"}
    mine = [d for d in log.guard if d.instruction_id in counted]
    repaired = sum(d.verdict is Verdict.REPAIR for d in mine)
    return {"guard_checked": len(mine), "guard_repaired": repaired,
            "guard_blocked": sum(d.verdict is Verdict.BLOCK for d in mine) + repaired}


def run_job(job: Job, watch: CallWatch | None = None) -> Outcome:
    """Run one job in a fresh :class:`EpisodeWorker` (for one-off runs and tests)."""
    worker = EpisodeWorker(watch)
    try:
        return worker.run(job)
    finally:
        worker.close()
