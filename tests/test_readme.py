"""The README's Python API example runs as it is written (real SUMO, real agents), and what it
returns and writes is what the README says: ``icrsumo.load_suite``, ``icrsumo.run_episode``
with a callback, ``icrsumo.evaluate`` into the same folder, and a rerun that finds everything."""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import shutil
from pathlib import Path

import pytest

import icrsumo
from icrsumo.core.defaults import LOOP_VERSION
from icrsumo.evaluation import EvalResult
from icrsumo.world.convert import CONVERTER_VERSION
from icrsumo.world.scenario import Scenario

pytestmark = pytest.mark.sumo

README = Path(__file__).resolve().parents[1] / "docs" / "api.md"  # the page that holds the example


def _api_example() -> str:
    text = README.read_text(encoding="utf-8")
    m = re.search(r"<!-- api-example -->\n```python\n(.*?)```", text, re.S)
    assert m, "README: the Python API example block (after <!-- api-example -->) is missing"
    return m.group(1)


def test_the_python_api_example_runs(tmp_path, converted, capsys):
    # the tiny suite converted by this session already (the same options): load_suite reuses it
    shutil.copytree(converted["tiny"], tmp_path / "icr_out" / "scenarios")
    ns: dict = {"__name__": "readme_example"}
    printed = io.StringIO()
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        with contextlib.redirect_stdout(printed):
            exec(compile(_api_example(), str(README), "exec"), ns)  # noqa: S102 - the README's own code
    finally:
        os.chdir(cwd)
    out = tmp_path / "icr_out"
    lines = printed.getvalue().splitlines()
    assert len(lines) == 3 and lines[1] == "8 0"  # the comment in the README

    # load_suite
    suite = ns["suite"]
    assert isinstance(suite, icrsumo.Suite) and suite.skipped == () and len(suite.route_ids) == 16
    assert all(isinstance(s, Scenario) for s in suite.scenarios) and ns["sc"].route_id == "tiny_003"
    assert [(s.family, s.k) for s in suite.instruction_sets["tiny_003"]] == [
        ("baseline", 0), ("paraphrase", 0), ("ambiguity", 0), ("noise", 0), ("misleading", 0)]
    with pytest.raises(KeyError, match="no route 'nope'"):
        suite.scenario("nope")

    # run_episode with a callback
    log, result = ns["log"], ns["result"]
    assert log.route_id == "tiny_003" and log.family == "misleading" and len(log.t) > 10
    assert lines[0].split()[1:] == [str(result.termination), str(result.termination_class),
                                    str(ns["junctions"].steps)]
    assert ns["junctions"].steps > 0

    # evaluate: the result and the files
    run = ns["run"]
    assert isinstance(run, EvalResult) and run.out == Path("icr_out")
    assert (run.episodes, run.ran, run.done, run.crashed) == (8, 8, 8, 0) and run.inference == {}
    assert run.summary == json.loads((out / "summary.json").read_text())
    assert set(run.summary["agents"]) == {"route-oracle", "instruction-follower"}
    assert run.summary["agents"]["route-oracle"]["families"]["misleading"]["dDS"] == 0  # blind to wording
    for name in ("config.json", "results.sqlite", "results.md", "results.csv", "results.tex", "episodes.csv",
                 "figures/rollout_tiny_003.png", "leaderboard/route-oracle_misleading.json"):
        assert (out / name).is_file(), name
    config = json.loads((out / "config.json").read_text())
    agents = config.pop("agents")
    assert config == {"run": "evaluate", "suite": "tiny", "seed": 2026, "k": 1, "traffic": "normal",
                      "scoring": "lb1", "converter": CONVERTER_VERSION, "loop": LOOP_VERSION}
    assert {n: a["spec"] for n, a in agents.items()} == {"route-oracle": "route-oracle",
                                                         "instruction-follower": "instruction-follower"}
    assert all(a["fingerprint"].startswith("sha256:") for a in agents.values())

    # a rerun finds everything stored: nothing runs, the same summary; not quiet, the table prints
    summary = (out / "summary.json").read_bytes()
    capsys.readouterr()
    again = icrsumo.evaluate(suite="tiny", agents=["route-oracle", "instruction-follower"],
                             families="misleading", k=1, routes=["tiny_003", "tiny_012"], out=out,
                             workers=2, quiet=False)
    assert (again.episodes, again.ran, again.done) == (8, 0, 8)
    assert (out / "summary.json").read_bytes() == summary and again.summary == run.summary
    assert "instruction-follower" in capsys.readouterr().out
