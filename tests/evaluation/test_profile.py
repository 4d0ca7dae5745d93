"""EvalOptions.profile: where an evaluation's wall time goes (icrsumo.evaluation.profile), never
stored, the episodes the same with it as without."""

from __future__ import annotations

import math
import time

import pytest

from icrsumo.agents.registry import DEFAULT_AGENT
from icrsumo.core.vocab import Phase
from icrsumo.evaluation import EvalOptions, run_evaluation
from icrsumo.evaluation.profile import JobTiming, Round, account
from icrsumo.results.store import ResultStore


def _job(pid: int, start: float, end: float) -> JobTiming:
    span = end - start
    return JobTiming({Phase.SUMO_START: 0.25 * span, Phase.ACT: 0.75 * span}, start, end, pid)


def test_every_second_of_every_slot_goes_to_one_phase():
    # 2 slots from 0 to 10; the pool runs from 1 to 9: worker 7 two jobs with a gap, worker 8 one job
    rounds = [Round(1.0, 9.0, (_job(7, 4.5, 8.0), _job(7, 2.0, 4.0), _job(8, 3.0, 5.0)))]
    p = account(0.0, 10.0, 2, rounds)
    assert p.wall_s == 10.0 and p.slots == 2 and len(p.episodes) == 3
    assert p.phases[Phase.BEFORE] == 2.0 and p.phases[Phase.AFTER] == 2.0
    assert p.phases[Phase.WORKER_START] == (2.0 - 1.0) + (3.0 - 1.0)
    assert p.phases[Phase.STORING] == 0.5
    assert p.phases[Phase.IDLE] == (9.0 - 8.0) + (9.0 - 5.0)
    assert p.phases[Phase.ACT] == 0.75 * (2.0 + 3.5 + 2.0)
    assert math.isclose(p.phases[Phase.OTHER], 0.0, abs_tol=1e-12)
    assert math.isclose(sum(p.phases.values()), 20.0)
    # a slot that ran nothing in a round is idle all of it; a run without rounds is the parent's
    one = account(0.0, 10.0, 3, rounds)
    assert one.phases[Phase.IDLE] == p.phases[Phase.IDLE] + 8.0
    assert account(0.0, 4.0, 2, []).phases[Phase.BEFORE] == 8.0


@pytest.mark.sumo
def test_a_profiled_run_stores_the_same_episodes_and_nothing_more(suite, tmp_path):
    def run(out, **kw):
        opts = EvalOptions(out=out, suite=str(suite), agents=(DEFAULT_AGENT, "route-oracle"),
                           families=("noise",), k=1, quiet=True, **kw)
        t0 = time.perf_counter()
        res = run_evaluation(opts)
        return res, time.perf_counter() - t0

    plain, _ = run(tmp_path / "plain", workers=1)
    timed, outer = run(tmp_path / "timed", workers=2, profile=True)
    # the same episodes, byte for byte, and the same outputs: the profile is stored nowhere
    assert plain.profile is None and timed.digest == plain.digest
    summary = "summary.json"
    assert (tmp_path / "timed" / summary).read_bytes() == (tmp_path / "plain" / summary).read_bytes()
    with ResultStore(tmp_path / "plain" / "results.sqlite") as a, \
            ResultStore(tmp_path / "timed" / "results.sqlite") as b:
        recs = a.records()
        assert len(recs) == 4 and recs == b.records()
        for r in recs:
            key = (r.agent, r.route_id, r.family, r.k, r.seed)
            assert a.log(*key) == b.log(*key)

    def files(out):
        return sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file() and p.suffix != ".lock")

    assert files(tmp_path / "timed") == files(tmp_path / "plain")
    # the profile: every slot's time in one phase, the loop's phases measured
    p = timed.profile
    assert p.slots == 2 and 0 < p.wall_s <= outer and len(p.episodes) == 4
    assert math.isclose(sum(p.phases.values()), 2 * p.wall_s, rel_tol=1e-9)
    assert abs(p.phases[Phase.OTHER]) <= 0.01 * 2 * p.wall_s
    for phase in (Phase.SUMO_START, Phase.SUMO_STEP, Phase.SUMO_IO, Phase.OBSERVATION, Phase.BEV, Phase.ACT,
                  Phase.RULES, Phase.RECORDING, Phase.SCORING, Phase.LOGGING, Phase.BEFORE, Phase.AFTER):
        assert p.phases[phase] > 0, phase
    for e in p.episodes:
        assert math.isclose(sum(e.phases.values()), e.end - e.start, rel_tol=1e-9)
        assert e.steps > 100 and e.sim_s > 5 and e.scenario
