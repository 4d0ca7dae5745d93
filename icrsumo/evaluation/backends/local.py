"""The local backend: worker processes on this machine (one SUMO each), fed one job at a time
over a pipe, with a watchdog in the parent that kills and replaces a worker whose agent call (or
guard call) overruns the timeout (:class:`~icrsumo.agents.hosting.watch.SlotWatch`) or that dies."""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import os
import signal
import threading
import time
from collections.abc import Iterator
from typing import Any

from icrsumo.agents.hosting.watch import AGENT, SlotWatch, Unwatched, overran, overran_by, timeout_message
from icrsumo.core.errors import raise_interrupted
from icrsumo.core.procs import die_with_parent
from icrsumo.core.vocab import ErrorKind

from ..execute import EpisodeWorker, Outcome, row_guard
from ..plan import Job


def _worker_main(conn: multiprocessing.connection.Connection, slot: Any, parent: int,
                 caller: Any = None) -> None:
    """A pool worker: run the jobs it is sent, one at a time, until it is sent None; it dies
    with its parent (however the parent ends, kill -9 included)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    for sig in (signal.SIGTERM, signal.SIGHUP):   # the parent's handlers, inherited by fork
        signal.signal(sig, signal.SIG_DFL)
    die_with_parent(parent)
    worker = EpisodeWorker(SlotWatch(slot, caller))
    try:
        while True:
            try:
                job = conn.recv()
            except (EOFError, OSError):
                return
            if job is None:
                return
            conn.send(worker.run(job))
    finally:
        worker.close()


class _Process:
    """One worker process, its pipe, its watch slots (when its call began; whether the agent or
    its guard called) and the job it runs."""

    def __init__(self, ctx: Any) -> None:
        self.slot = ctx.Value("d", 0.0, lock=False)
        self.caller = ctx.Value("i", 0, lock=False)
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker_main, args=(child, self.slot, os.getpid(), self.caller),
                                daemon=True)
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


def _run_in_process(jobs: list[Job]) -> Iterator[tuple[Job, Outcome]]:
    """Run ``jobs`` here, one at a time. Ctrl-C raises :class:`~icrsumo.core.errors.Interrupted` while
    they run (from the main thread), so that a ``KeyboardInterrupt`` raised by agent code is told
    apart from the user's and stored as a crash."""
    main = threading.current_thread() is threading.main_thread()
    old = signal.signal(signal.SIGINT, raise_interrupted) if main else None
    worker = EpisodeWorker(Unwatched())
    try:
        for job in jobs:
            yield job, worker.run(job)
    finally:
        worker.close()
        if main:
            signal.signal(signal.SIGINT, old)


def run_local(jobs: list[Job], workers: int, timeout: float | None = None) -> Iterator[tuple[Job, Outcome]]:
    """Run ``jobs`` in ``workers`` processes, yielding each job with its outcome as it ends; a
    worker whose agent call overruns ``timeout`` s (or that dies) is replaced and its episode
    reported as timed out (or crashed). ``workers == 1`` without a timeout runs in this
    process."""
    if workers == 1 and timeout is None:
        yield from _run_in_process(jobs)
        return
    if not jobs:
        return
    ctx = multiprocessing.get_context()
    it = iter(jobs)
    busy: dict = {}
    pool: list[_Process] = []

    def feed(w: _Process) -> None:
        job = next(it, None)
        if job is not None:
            w.send(job)
            busy[w.conn] = w

    def replace(w: _Process) -> _Process:
        w.stop(kill=True)
        pool[pool.index(w)] = new = _Process(ctx)
        return new

    try:
        for _ in range(min(workers, len(jobs))):
            pool.append(_Process(ctx))
            feed(pool[-1])
        while busy:
            for conn in multiprocessing.connection.wait(list(busy), timeout=0.2):
                w = busy.pop(conn)
                job, w.job = w.job, None
                try:
                    outcome = conn.recv()
                except (EOFError, OSError):
                    w.proc.join(timeout=5)
                    outcome = Outcome.failure(
                        ErrorKind.WORKER_DIED, f"WorkerDied: the worker process died (exit code "
                                               f"{w.proc.exitcode}) while running this episode")
                    w = replace(w)
                yield job, outcome
                feed(w)
            if timeout is not None:
                now = time.monotonic()
                for conn, w in list(busy.items()):
                    if overran(w.slot, timeout, now):
                        busy.pop(conn)
                        job = w.job
                        who = overran_by(w.caller, row_guard(job))
                        kind = "AgentTimeout" if who == AGENT else "GuardTimeout"
                        w = replace(w)
                        yield job, Outcome.failure(
                            ErrorKind.AGENT_TIMEOUT, f"{kind}: {timeout_message(timeout, who)} "
                                                     f"(its worker process was stopped)")
                        feed(w)
    finally:
        for w in pool:
            w.stop(kill=w.conn in busy)
