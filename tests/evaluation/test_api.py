"""The Python API on real SUMO: ``icrsumo.load_suite`` then ``icrsumo.evaluate`` into the same
folder (the README's example), its result, its files, its progress output, and a rerun."""

from __future__ import annotations

import json

import pytest

import icrsumo
from icrsumo.evaluation import EvalResult
from icrsumo.scenario import Scenario

pytestmark = pytest.mark.sumo

ROUTES = ["tiny_003", "tiny_012"]


def test_load_suite_then_evaluate(tmp_path, capsys):
    out = tmp_path / "icr_out"
    # the README's example (Python API)
    suite = icrsumo.load_suite("tiny", out=out, k=1)
    assert set(ROUTES) <= set(suite.route_ids)
    sc = suite.scenario("tiny_003")
    noise = suite.instruction_set("tiny_003", "noise", 0)
    result = icrsumo.evaluate(suite="tiny", agents=["route-oracle"], families=["noise"], k=1,
                              routes=ROUTES, out=out, workers=2, quiet=False)
    delta = result.summary["agents"]["route-oracle"]["families"]["noise"]["dDS"]

    # the suite
    assert isinstance(suite, icrsumo.Suite) and suite.out == out and suite.skipped == ()
    assert all(isinstance(s, Scenario) for s in suite.scenarios)
    assert isinstance(sc, Scenario) and sc.route_id == "tiny_003" and sc.length > 0
    sets = suite.instruction_sets["tiny_003"]
    assert [(s.family, s.k) for s in sets] == [("baseline", 0), ("paraphrase", 0), ("ambiguity", 0),
                                               ("noise", 0), ("misleading", 0)]
    assert noise.family == "noise" and noise.route_id == "tiny_003" and noise.instructions
    with pytest.raises(KeyError, match="no route 'nope'"):
        suite.scenario("nope")

    # the result and the files
    assert isinstance(result, EvalResult) and result.out == out
    assert (result.episodes, result.ran, result.done, result.crashed) == (4, 4, 4, 0)
    assert result.inference == {} and delta == 0
    assert result.summary == json.loads((out / "summary.json").read_text())
    assert result.summary["episodes"] == {"done": 4, "crashed": 0} and result.summary["families"] == ["noise"]
    for name in ("config.json", "results.sqlite", "results.md", "results.csv", "results.tex", "episodes.csv",
                 "figures/rollout_tiny_003.png", "leaderboard/route-oracle_noise.json"):
        assert (out / name).is_file(), name
    assert json.loads((out / "config.json").read_text()) == {"suite": "tiny", "seed": 2026, "k": 1,
                                                             "traffic": "normal"}
    # not quiet: progress on stderr, the table on stdout
    captured = capsys.readouterr()
    assert "4/4" in captured.err and "episode" in captured.err
    assert "route-oracle" in captured.out

    # a rerun finds everything stored: nothing runs, nothing is printed, the same summary
    summary = (out / "summary.json").read_bytes()
    again = icrsumo.evaluate(suite="tiny", agents="route-oracle", families="noise", k=1, routes=ROUTES,
                             out=out, workers=2)
    assert (again.episodes, again.ran, again.done) == (4, 0, 4)
    assert (out / "summary.json").read_bytes() == summary and again.summary == result.summary
    assert capsys.readouterr() == ("", "")
