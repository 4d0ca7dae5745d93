"""A crashed episode keeps the log of its steps up to the crash: stored beside the crashed
record, scored by the Leaderboard 1.0 results file as the leaderboard scores an 'Agent crashed'
route (the criteria's partial RC and IS), and left out of icrsumo's own tables as before."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

from icrsumo.agents.base import Action
from icrsumo.agents.privileged import RouteOracle
from icrsumo.evaluation import EvalOptions, run_evaluation
from icrsumo.evaluation.digests import store_hashes
from icrsumo.results.store import ResultStore
from icrsumo.scoring.lb1 import LB1

pytestmark = pytest.mark.sumo

TOOLS = Path(__file__).parents[2] / "tools"


class ExplodesAfter40(RouteOracle):
    """Follows the route for 40 decisions, then raises on every later one."""

    name = "explodes-after-40"

    def reset(self, info) -> None:
        super().reset(info)
        self.n = 0

    def act(self, obs) -> Action:
        self.n += 1
        if self.n > 40:
            raise RuntimeError(f"exploded on decision {self.n}")
        return super().act(obs)


class ExplodesAtReset(RouteOracle):
    """Raises before the episode's first step."""

    name = "explodes-at-reset"

    def reset(self, info) -> None:
        raise RuntimeError("no weights")


def test_an_agent_crash_is_stored_with_its_partial_log_and_scored_by_the_leaderboard(suite, tmp_path):
    out = tmp_path / "o"
    result = run_evaluation(EvalOptions(out=out, suite=str(suite), agents=(ExplodesAfter40, ExplodesAtReset),
                                        families=("noise",), k=1, quiet=True))
    assert (result.episodes, result.done, result.crashed) == (4, 0, 4)
    assert json.loads((out / "summary.json").read_text())["episodes"] == {"done": 0, "crashed": 4}
    with ResultStore(out / "results.sqlite", readonly=True) as store:
        recs = {(r.agent, str(r.family)): r for r in store.records()}
        logs = {key: store.episode_log(r.agent, r.route_id, r.family, r.k, r.seed) for key, r in recs.items()}
        kinds = {e.key[0]: e.kind for e in store_hashes(store)}
    for fam in ("baseline", "noise"):
        r, log = recs[("explodes-after-40", fam)], logs[("explodes-after-40", fam)]
        # retried once (it may have been a transient fault), the second attempt's log kept
        assert (r.status, r.attempts, r.ds, r.rc, r.termination) == ("crashed", 2, 0.0, 0.0, "")
        assert r.message.startswith("RuntimeError: exploded on decision 41 at test_crash_logs.py:")
        assert (len(log.t), log.termination, log.message) == (81, "agent_error", r.message)
        assert r.length > 0
        early = recs[("explodes-at-reset", fam)]
        assert early.status == "crashed" and early.message.startswith("RuntimeError: no weights")
        assert logs[("explodes-at-reset", fam)] is None  # no step: no log
    assert kinds == {"explodes-after-40": "log", "explodes-at-reset": "no-log"}
    # the results file: the partial RC / IS of that log, the agent's crash
    cp = json.loads((out / "leaderboard" / "explodes-after-40_baseline.json").read_text())
    (route,) = cp["_checkpoint"]["records"]
    partial = LB1.score(logs[("explodes-after-40", "baseline")])
    assert route["status"] == "Failed - Agent crashed" and 0 < partial.rc < 100
    assert route["scores"] == {"score_route": partial.rc, "score_penalty": partial.is_,
                               "score_composed": partial.ds}
    assert route["meta"]["duration_game"] == partial.duration == 4.0
    assert (cp["entry_status"], cp["eligible"]) == ("Finished with agent errors", True)
    early = json.loads((out / "leaderboard" / "explodes-at-reset_baseline.json").read_text())
    assert early["_checkpoint"]["records"][0]["scores"] == {"score_route": 0.0, "score_penalty": 1.0,
                                                            "score_composed": 0.0}
    # icrsumo's own tables: crashed, not scored
    with (out / "episodes.csv").open(encoding="utf-8") as f:
        rows = [row for row in csv.DictReader(f) if row["agent"] == "explodes-after-40"]
    assert [(row["status"], row["rc"], row["ds"], row["termination"]) for row in rows] == [
        ("crashed", "0.0", "0.0", "")] * 2
    # the leaderboard's code transcribed (tests/lb1_reference.py) agrees
    proc = subprocess.run([sys.executable, str(TOOLS / "check_lb1.py"), str(out)], capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "4 results files" in proc.stdout and "; 0 differ" in proc.stdout


def test_show_replays_a_crashed_episode_up_to_its_crash(suite, tmp_path, capsys):
    """``icrsumo show`` replays a crashed episode stored with its log up to the crash, byte for
    byte, and says it crashed; one that crashed before its first step has nothing to replay."""
    from icrsumo.app.cli.main import main

    here = Path(__file__).resolve()
    out = tmp_path / "o"
    run_evaluation(EvalOptions(out=out, suite=str(suite), agents=(f"{here}:ExplodesAfter40",
                                                                  f"{here}:ExplodesAtReset"),
                               families=("noise",), k=1, quiet=True))
    with ResultStore(out / "results.sqlite", readonly=True) as store:
        route = next(r.route_id for r in store.records())
    show = ["show", str(out), "--route", route, "--family", "baseline", "--agent"]
    code = main([*show, "explodes-after-40", "--dir", str(tmp_path / "show")])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    printed = printed.out
    assert "crashed: RuntimeError: exploded on decision 41" in printed
    assert "reproduces the stored log byte for byte" in printed
    code = main([*show, "explodes-at-reset", "--dir", str(tmp_path / "show2")])
    assert code == 2 and "crashed before its first step" in capsys.readouterr().err
