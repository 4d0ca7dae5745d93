"""Execution backends: run a list of jobs and yield ``(job, Outcome)`` pairs as episodes end.

* :func:`~icrsumo.evaluation.backends.local.run_local`: worker processes on this machine, with
  the parent's watchdog for hung agent calls;
* :func:`~icrsumo.evaluation.backends.ray.run_ray`: Ray actors, with SIGALRM for hung calls.
"""

from __future__ import annotations

from collections.abc import Iterator

from ..execute import Outcome
from ..options import EvalOptions
from ..plan import Job


def run_jobs(jobs: list[Job], opts: EvalOptions) -> Iterator[tuple[Job, Outcome]]:
    """Run ``jobs`` on ``opts.backend`` with ``opts.workers`` workers and ``opts.agent_timeout``."""
    if opts.backend == "ray":
        from .ray import run_ray

        return run_ray(jobs, opts.workers, opts.address, opts.agent_timeout)
    from .local import run_local

    return run_local(jobs, opts.workers, opts.agent_timeout)
