"""Episode jobs give typed outcomes, and the retry rule reads their kind: a raising agent is
crashed (retried once), a hung one timed out (never retried), a dead worker crashed with
worker_died; the local pool's watchdog and Ray's SIGALRM guard agent calls."""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from icrsumo.agents.base import AgentTimeout, EpisodeInfo, Observation
from icrsumo.agents.hosting.watch import AlarmWatch
from icrsumo.core.errors import describe
from icrsumo.core.vocab import ErrorKind, OutcomeStatus
from icrsumo.evaluation import EvalOptions, Job, Outcome, plan_jobs, run_evaluation
from icrsumo.evaluation.backends.local import run_local
from icrsumo.evaluation.execute import WatchedAgent, run_job
from icrsumo.evaluation.plan import prepare_suite
from icrsumo.results.store import ResultStore

pytestmark = pytest.mark.sumo

AGENTS = Path(__file__).parents[1] / "data" / "agents" / "user_agents.py"
INFO = EpisodeInfo("r", "town", "net.xml", 0.05, 0.1, 7)
#: the stored message of an agent call that overran a 1 s limit under the local pool's watchdog
HUNG = "AgentTimeout: agent did not answer within 1 s (its worker process was stopped)"


def _obs(t: float = 20.05) -> Observation:
    bev = np.zeros((7, 128, 128), np.uint8)
    return Observation(t=t, bev=bev, speed=3.25, instruction="At the T-junction, turn left.",
                       instruction_id=0, notice="")


def _user_agents():
    sys.path.insert(0, str(AGENTS.parent))
    try:
        import user_agents
    finally:
        sys.path.remove(str(AGENTS.parent))
    return user_agents


@pytest.fixture(scope="module")
def baseline_job(suite, tmp_path_factory):
    """``make(cls)``: the baseline episode job of tiny_003 for user agent class ``cls``."""
    opts = EvalOptions(out=tmp_path_factory.mktemp("jobs"), suite=str(suite), k=1, quiet=True)
    prep = prepare_suite(opts)

    def make(cls: str) -> Job:
        spec = f"{AGENTS}:{cls}"
        jobs = plan_jobs(replace(opts, agents=(spec,)), prep.scenarios, prep.instructions,
                         {spec: cls.lower()})
        return next(j for j in jobs if j.family == "baseline")

    return make


def test_a_finished_episode_is_done_with_its_record_and_log(baseline_job):
    out = run_job(baseline_job("Cruise"))
    assert out.status is OutcomeStatus.DONE and out.error_kind is None and out.message == ""
    rec = out.record
    assert (rec.agent, rec.route_id, rec.family, rec.k, rec.status, rec.attempts) == \
        ("cruise", "tiny_003", "baseline", 0, "done", 1)
    assert out.log_json.startswith("{") and rec.duration > 0


def _partial(out: Outcome, steps: int) -> None:
    """``out`` carries the crashed record (no scores, the route's length) and the log of the
    ``steps`` steps recorded before the crash, ended agent_error with the outcome's message."""
    from icrsumo.results.logs import loads_log

    rec = out.record
    assert (rec.status, rec.ds, rec.rc, rec.is_, rec.termination, rec.message) == (
        "crashed", 0.0, 0.0, 0.0, "", out.message)
    assert rec.length > 0
    log = loads_log(out.log_json)
    assert (len(log.t), log.termination, log.message) == (steps, "agent_error", out.message)


def test_a_raising_agent_is_crashed_with_an_error_kind(baseline_job):
    out = run_job(baseline_job("Raises"))
    assert out.status is OutcomeStatus.CRASHED and out.error_kind is ErrorKind.ERROR
    assert out.message.startswith("RuntimeError: agent exploded at user_agents.py:")
    _partial(out, 5)  # it raised on its 3rd decision, which read step 4


def test_a_hang_under_sigalrm_is_timed_out(baseline_job):
    t0 = time.perf_counter()
    out = run_job(baseline_job("Hangs"), AlarmWatch(0.5))
    assert time.perf_counter() - t0 < 30
    assert out.status is OutcomeStatus.TIMED_OUT and out.error_kind is ErrorKind.AGENT_TIMEOUT
    assert out.message.startswith("AgentTimeout: agent did not answer within 0.5 s at ")
    _partial(out, 5)  # the loop stopped cleanly: its steps are kept


def test_the_local_watchdog_and_a_dead_worker_give_typed_outcomes(baseline_job):
    jobs = [baseline_job("Hangs"), baseline_job("Dies"), baseline_job("Cruise")]
    outcomes = {job.agent: out for job, out in run_local(jobs, workers=2, timeout=1.0)}
    hung, died, fine = outcomes["hangs"], outcomes["dies"], outcomes["cruise"]
    assert (hung.status, hung.error_kind) == (OutcomeStatus.TIMED_OUT, ErrorKind.AGENT_TIMEOUT)
    assert hung.message == HUNG and hung.log_json == ""  # its process was stopped: no log
    assert (died.status, died.error_kind) == (OutcomeStatus.CRASHED, ErrorKind.WORKER_DIED)
    assert died.message == "WorkerDied: the worker process died (exit code 3) while running this episode"
    assert fine.status is OutcomeStatus.DONE


def test_outcome_of_an_error_reads_its_type():
    try:
        raise AgentTimeout("agent did not answer within 2 s")
    except AgentTimeout as err:
        timed_out = Outcome.of_error(err)
        message = describe(err)
    assert timed_out == Outcome(OutcomeStatus.TIMED_OUT, error_kind=ErrorKind.AGENT_TIMEOUT, message=message)
    assert Outcome.of_error(ValueError("x")).status is OutcomeStatus.CRASHED
    # the kind decides, never the text: a message that merely looks like a timeout is an error
    assert Outcome.of_error(RuntimeError("AgentTimeout: no")).error_kind is ErrorKind.ERROR


def test_hung_dying_and_raising_agents_are_crashes_and_the_run_completes(suite, tmp_path):
    """The retry rule: a timed-out episode is stored at once, a raising agent or a dead worker
    gets a second attempt; the other agents' episodes are unaffected."""
    agents = (f"{AGENTS}:Hangs", f"{AGENTS}:Dies", f"{AGENTS}:Raises", f"{AGENTS}:Cruise")
    t0 = time.perf_counter()
    result = run_evaluation(EvalOptions(out=tmp_path, suite=str(suite), agents=agents, families=("noise",),
                                        k=1, workers=2, quiet=True, agent_timeout=1.0))
    assert time.perf_counter() - t0 < 90
    assert (result.episodes, result.ran, result.done, result.crashed) == (8, 8, 2, 6)
    assert result.summary["episodes"] == {"done": 2, "crashed": 6}
    with ResultStore(tmp_path / "results.sqlite") as s:
        recs = {(r.agent, r.family): r for r in s.records()}
    for fam in ("baseline", "noise"):
        hung, died, raised = recs[("hangs", fam)], recs[("dies", fam)], recs[("raises", fam)]
        assert hung.status == "crashed" and hung.attempts == 1  # a hang is not retried
        assert hung.message == HUNG
        assert died.status == "crashed" and died.attempts == 2 and "worker process died" in died.message
        assert raised.status == "crashed" and raised.attempts == 2
        assert raised.message.startswith("RuntimeError: agent exploded at user_agents.py:")
        assert recs[("cruise", fam)].status == "done" and recs[("cruise", fam)].attempts == 1


def test_alarm_timeout_where_no_parent_watches():
    """Ray workers (no watching parent): SIGALRM interrupts a hung call in the main thread."""
    agent = WatchedAgent(_user_agents().Hangs(), AlarmWatch(0.3))
    assert (agent.name, agent.privileged, agent.needs_route) == ("hangs", False, False)
    agent.reset(INFO)
    agent.act(_obs())
    agent.act(_obs())
    t0 = time.perf_counter()
    with pytest.raises(AgentTimeout, match="agent did not answer within 0.3 s"):
        agent.act(_obs())
    assert time.perf_counter() - t0 < 2


def test_the_wrapper_forwards_what_the_episode_reads():
    from icrsumo.agents.privileged import RouteOracle

    oracle = WatchedAgent(RouteOracle(), AlarmWatch(None))
    assert (oracle.name, oracle.privileged) == ("route-oracle", True)
    assert oracle.needs_route == getattr(RouteOracle, "needs_route", False)
