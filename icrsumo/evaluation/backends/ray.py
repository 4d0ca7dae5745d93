"""The Ray backend: ``workers`` Ray actors (one CPU each, on this machine or on the cluster at
``address``), each an :class:`~icrsumo.evaluation.execute.EpisodeWorker` whose agent calls are
interrupted by SIGALRM after the timeout (:class:`~icrsumo.agents.hosting.watch.AlarmWatch`: no
parent watches them). An actor that dies is replaced; its episode is reported as crashed."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

from icrsumo.agents.hosting.watch import AlarmWatch
from icrsumo.core.errors import Field, InputError
from icrsumo.core.vocab import ErrorKind

from ..execute import EpisodeWorker, Outcome
from ..plan import Job


class RayWorker:
    """The body of one Ray actor: an episode worker that lives as long as the actor."""

    def __init__(self, timeout: float | None) -> None:
        self.worker = EpisodeWorker(AlarmWatch(timeout))

    def run(self, job: Job) -> Outcome:
        return self.worker.run(job)


def run_ray(jobs: list[Job], workers: int, address: str | None = None,
            timeout: float | None = None) -> Iterator[tuple[Job, Outcome]]:
    """Run ``jobs`` on ``workers`` Ray actors, yielding each job with its outcome as it ends.
    Starts Ray (a local instance with ``workers`` CPUs, or connects to ``address``) unless it
    is running, and shuts down what it started."""
    try:
        import ray
        from ray.exceptions import RayError
    except ImportError:
        raise InputError(f"{Field('backend')} ray", "", "Ray is not installed",
                         "pip install 'icrsumo[ray]'") from None
    if not jobs:
        return
    started = not ray.is_initialized()
    if started:
        if address:
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
        else:
            # "local": always a private instance of our own, never a cluster that RAY_ADDRESS or a
            # leftover session file of an earlier (killed) Ray run points at
            ray.init(address="local", num_cpus=workers, include_dashboard=False, log_to_driver=False)
    actor_cls = ray.remote(num_cpus=1)(RayWorker)
    try:
        idle = [actor_cls.remote(timeout) for _ in range(min(workers, len(jobs)))]
        refs: dict = {}
        it = iter(jobs)

        def feed() -> None:
            while idle:
                job = next(it, None)
                if job is None:
                    return
                actor = idle.pop()
                refs[actor.run.remote(job)] = (job, actor)

        feed()
        while refs:
            ready, _ = ray.wait(list(refs), num_returns=1)
            for ref in ready:
                job, actor = refs.pop(ref)
                try:
                    outcome = ray.get(ref)
                except RayError as err:  # the actor died (e.g. the agent killed its process)
                    outcome = Outcome.failure(ErrorKind.WORKER_DIED, f"WorkerDied: the Ray worker died "
                                              f"while running this episode ({type(err).__name__})")
                    with contextlib.suppress(Exception):
                        ray.kill(actor)
                    actor = actor_cls.remote(timeout)
                idle.append(actor)
                yield job, outcome
                feed()
    finally:
        if started:
            ray.shutdown()
