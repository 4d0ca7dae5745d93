"""Where an evaluation's wall time goes (``EvalOptions.profile``, for ``tools/benchmark.py
--protocol``): each worker times its jobs' phases (:class:`~icrsumo.sim.callbacks.PhaseClock`)
and returns them with the job's outcome; the parent adds what happens around the jobs (worker
start-up, storing between jobs, idle workers, its own work before and after). Nothing of it is
stored: the results, logs and outputs are the same with or without a profile.

Times are ``time.perf_counter`` stamps, one clock for every process of the machine (Linux:
``CLOCK_MONOTONIC``), so a worker's stamps and the parent's can be compared.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from icrsumo.core.vocab import Phase

#: the closed loop's phases (per step), as against start-up, per-episode and pool phases
LOOP_PHASES = (Phase.SUMO_STEP, Phase.SUMO_IO, Phase.CONTROL, Phase.OBSERVATION, Phase.BEV, Phase.ACT,
               Phase.RULES, Phase.RECORDING)


@dataclass(frozen=True)
class JobTiming:
    """What a worker measured of one job: ``phases`` (phase -> s), its ``start`` and ``end``
    stamps (the phases add up to ``end - start``), the worker process (``pid``), the episode's
    ``steps`` and simulated seconds (``sim_s``; 0 for a failed job) and its ``scenario`` folder."""

    phases: Mapping[str, float]
    start: float
    end: float
    pid: int
    steps: int = 0
    sim_s: float = 0.0
    scenario: str = ""


@dataclass(frozen=True)
class Round:
    """One pass of the backend over a queue of jobs (a second pass runs the retried ones):
    from ``start`` (before its workers start) to ``end`` (after they stopped), the timings of
    the jobs that returned one."""

    start: float
    end: float
    jobs: tuple[JobTiming, ...]


@dataclass(frozen=True)
class RunProfile:
    """An evaluation's wall time split into phases (:class:`~icrsumo.core.vocab.Phase`):
    ``wall_s`` from the call's start to its end, ``slots`` workers; ``phases``: phase -> seconds
    summed over the slots, adding up to ``wall_s * slots`` (``other``: what no phase covers, e.g.
    the time between a retry round and the last, or of a worker replaced after a timeout);
    ``episodes``: the timing of every job run, in the order they ended."""

    wall_s: float
    slots: int
    phases: Mapping[str, float]
    episodes: tuple[JobTiming, ...] = ()

    @property
    def steps(self) -> int:
        return sum(e.steps for e in self.episodes)

    @property
    def loop_s(self) -> float:
        """Seconds of the closed loop's phases (:data:`LOOP_PHASES`), summed over the workers."""
        return sum(self.phases.get(p, 0.0) for p in LOOP_PHASES)


def account(began: float, ended: float, slots: int, rounds: Iterable[Round]) -> RunProfile:
    """The profile of a run from ``began`` to ``ended`` with ``slots`` workers: each slot's time
    given to exactly one phase. In a round, a worker process's time before its first job is
    ``worker_start``, its jobs' time their phases, the gaps between its jobs ``storing``, the
    time after its last job ``idle`` (as is a slot's whole round when it ran no job); before the
    first round ``before``, after the last ``after``; the rest ``other``."""
    rounds = list(rounds)
    phases: dict[str, float] = {p.value: 0.0 for p in Phase}
    if rounds:
        phases[Phase.BEFORE] = slots * (rounds[0].start - began)
        phases[Phase.AFTER] = slots * (ended - rounds[-1].end)
    else:
        phases[Phase.BEFORE] = slots * (ended - began)
    for r in rounds:
        by_pid: dict[int, list[JobTiming]] = {}
        for j in r.jobs:
            by_pid.setdefault(j.pid, []).append(j)
        for jobs in by_pid.values():
            jobs.sort(key=lambda j: j.start)
            phases[Phase.WORKER_START] += jobs[0].start - r.start
            phases[Phase.IDLE] += r.end - jobs[-1].end
            for prev, nxt in zip(jobs, jobs[1:]):
                phases[Phase.STORING] += nxt.start - prev.end
            for j in jobs:
                for p, s in j.phases.items():
                    phases[p] += s
        phases[Phase.IDLE] += max(slots - len(by_pid), 0) * (r.end - r.start)
    wall = ended - began
    phases[Phase.OTHER] = slots * wall - sum(v for p, v in phases.items() if p != Phase.OTHER)
    return RunProfile(wall, slots, phases, tuple(j for r in rounds for j in r.jobs))


@dataclass
class ProfileSink:
    """Collects a run's job timings round by round (the parent's side); made when the run
    starts, :meth:`finish` when it ends."""

    slots: int
    began: float = field(default_factory=time.perf_counter)
    rounds: list[Round] = field(default_factory=list)
    _start: float = 0.0
    _jobs: list[JobTiming] = field(default_factory=list)

    def round_start(self) -> None:
        self._start, self._jobs = time.perf_counter(), []

    def add(self, timing: JobTiming | None) -> None:
        if timing is not None:
            self._jobs.append(timing)

    def round_end(self) -> None:
        self.rounds.append(Round(self._start, time.perf_counter(), tuple(self._jobs)))

    def finish(self) -> RunProfile:
        return account(self.began, time.perf_counter(), self.slots, self.rounds)
