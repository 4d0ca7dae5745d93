"""``icrsumo evaluate``: the paired ICR protocol over routes x instruction sets x agents.

For every agent and route: the baseline sequence and K variants of each selected family, all
on the same scenario, seed and traffic. The out folder holds everything (reused on rerun):

    OUT/config.json         the run (evaluate, or attack and its constraint), suite, seed, k,
                            traffic, scoring, the converter's version (and the --baseline-bank
                            file's SHA-256): a rerun with another one is refused
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
crashed with "agent did not answer within N s", without a retry, and the run goes on. An
instruction guard's ``reset`` / ``check`` calls have the same limit, watched the same way
("guard NAME did not answer within N s").

Modules, one job each:

* :mod:`~icrsumo.evaluation.options`: :class:`EvalOptions` and their validation;
* :mod:`~icrsumo.evaluation.plan`: the out folder's configuration, the suite prepared into it,
  the :class:`Job` list;
* :mod:`~icrsumo.evaluation.execute`: one job in a worker -> a typed :class:`Outcome`;
* :mod:`~icrsumo.agents.hosting.watch`: how agent calls are guarded against hanging;
* :mod:`~icrsumo.evaluation.backends`: the local process pool and Ray;
* :mod:`~icrsumo.evaluation.inference`: batched inference processes for the workers;
* :mod:`~icrsumo.evaluation.progress`: the progress bar;
* :mod:`~icrsumo.evaluation.outputs`: summary, tables and figures;
* :mod:`~icrsumo.evaluation.run`: the orchestration (:func:`run_evaluation`,
  :func:`report_only`).

The Python API on top of it is :func:`icrsumo.evaluate` (:mod:`icrsumo.app.api`).
"""

from __future__ import annotations

from .execute import Outcome
from .options import AGENT_TIMEOUT, BACKENDS, EvalOptions
from .plan import Job, plan_jobs
from .run import EvalResult, report_only, run_evaluation

__all__ = ["AGENT_TIMEOUT", "BACKENDS", "EvalOptions", "EvalResult", "Job", "Outcome", "plan_jobs",
           "report_only", "run_evaluation"]
