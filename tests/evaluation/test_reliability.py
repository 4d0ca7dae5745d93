"""The error model of an evaluation: one-line errors for bad options, folders and stores
(exit status 2, nothing written), agent code that exits is a crash, crashed episodes repaired
in place with --retry-crashed, and reports that never drop stored results."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from icrsumo.app.cli.main import main
from icrsumo.core.errors import InputError
from icrsumo.core.types import EpisodeRecord
from icrsumo.evaluation import EvalOptions, report_only, run_evaluation
from icrsumo.results.store import ResultStore
from icrsumo.results.summary import EpisodeCounts

AGENTS = Path(__file__).parents[1] / "data" / "agents" / "user_agents.py"


def _one_line_error(capsys, argv: list[str]) -> str:
    """Run the CLI, assert exit status 2 and one stderr line without a traceback; the line."""
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2, err
    assert len(err) == 1 and "Traceback" not in err[0], err
    return err[0]


def _store(path: Path, n: int = 200) -> Path:
    """A real results store with ``n`` episodes (with logs, so it spans many pages)."""
    with ResultStore(path) as s:
        for i in range(n):
            s.put(EpisodeRecord("cruise", f"r{i:03d}", "noise", 0, 2026, status="done", ds=50.0, rc=60.0,
                                is_=0.8), json.dumps({"pad": "x" * 3000, "i": i}))
    return path


# ------------------------------------------------------------------ options and folders, no SUMO
@pytest.mark.parametrize("argv, expect", [
    (["--batch-inference", "tpu"], "unknown device"),
    (["--batch-inference", "cuda:7"], "CUDA device"),
    (["--agent-timeout", "nan"], "--agent-timeout"),
    (["--address", "ray://x:1"], "is for the ray backend"),
    (["--k", "0"], "out of range"),
    (["--seed", "-1"], "--seed: -1: out of range"),
    (["--seed", "99999999999999999999999"], "out of range"),
    (["--max-batch", "0"], "must be at least 1"),
    (["--family", ""], "--family: is empty"),
    (["--agent", " , "], "--agent: is empty"),
    (["--k", "x"], "invalid int value"),
    (["--traffic", "huge"], "invalid choice"),
    (["--agent", "remote:http://127.0.0.1:99999"], "bad port"),
    (["--agent", "remote:http://127.0.0.1:8765?timeout=inf"], "timeout must be"),
])
def test_bad_option_values_are_one_line_and_write_nothing(tmp_path, capsys, argv, expect):
    out = tmp_path / "o"
    line = _one_line_error(capsys, ["evaluate", "--out", str(out), "--quiet", *argv])
    assert expect in line
    assert not out.exists()


@pytest.mark.parametrize("command", [["evaluate", "--quiet"], ["convert-routes", "tiny"],
                                     ["generate", "somewhere"], ["collect"]])
def test_an_out_that_is_a_file_is_refused(tmp_path, capsys, command):
    target = tmp_path / "taken"
    target.write_text("mine")
    line = _one_line_error(capsys, [*command, "--out", str(target)])
    assert "is a file, not a folder" in line
    assert target.read_text() == "mine"


def test_an_out_under_a_file_is_refused(tmp_path, capsys):
    (tmp_path / "f").write_text("")
    assert "cannot be made" in _one_line_error(capsys, ["evaluate", "--out", str(tmp_path / "f" / "o")])


@pytest.mark.parametrize("port", ["70000", "-1", "http"])
def test_serve_agent_ports_out_of_range(capsys, port):
    assert "--port" in _one_line_error(capsys, ["serve-agent", "route-oracle", "--port", port])


@pytest.mark.parametrize("damage", ["garbage", "truncated", "empty-named-folder"])
def test_a_damaged_store_is_refused_before_anything_runs(tmp_path, capsys, damage):
    out = tmp_path / "o"
    out.mkdir()
    store = out / "results.sqlite"
    if damage == "garbage":
        store.write_bytes(b"this is not a database\n" * 100)
    elif damage == "truncated":
        data = _store(store).read_bytes()
        store.write_bytes(data[:len(data) // 2])
    else:
        store.mkdir()
    before = sorted(p.name for p in out.rglob("*"))
    line = _one_line_error(capsys, ["evaluate", "--out", str(out), "--quiet"])
    assert "results.sqlite" in line
    assert sorted(p.name for p in out.rglob("*")) == before  # no config.json, no scenarios


@pytest.mark.parametrize("config, expect", [
    ("{not json", "malformed JSON"),
    ("[1, 2]", "must be an object"),
    ('{"suite": "tiny", "k": "eight", "seed": 2026}', "k must be an integer"),
    ("\ufeff{}".encode("utf-16").decode("latin-1"), "UTF-16"),
])
def test_report_on_a_damaged_configuration(tmp_path, capsys, config, expect):
    out = tmp_path / "o"
    out.mkdir()
    _store(out / "results.sqlite", 3)
    (out / "config.json").write_bytes(config.encode("latin-1") if "UTF-16" in expect else config.encode())
    line = _one_line_error(capsys, ["report", str(out)])
    assert "config.json" in line and expect in line


@pytest.mark.parametrize("column, value", [("infractions", "{oops"), ("ds", "'high'"), ("status", "'maybe'"),
                                           ("infractions", "'[1, 2, 3]'"), ("ds", "9e999")])
def test_a_damaged_row_names_its_episode(tmp_path, capsys, column, value):
    import sqlite3

    out = tmp_path / "o"
    out.mkdir()
    _store(out / "results.sqlite", 3)
    (out / "config.json").write_text('{"suite": "tiny", "k": 1, "seed": 2026}')
    with sqlite3.connect(out / "results.sqlite") as db:
        quoted = value if value.startswith("'") or value[0].isdigit() else "'" + value + "'"
        db.execute(f"UPDATE episodes SET {column} = {quoted} WHERE route_id = 'r001'")
    line = _one_line_error(capsys, ["report", str(out)])
    assert "cruise/r001/noise/0/2026" in line


def test_a_database_that_is_not_a_store_and_a_config_with_a_key_twice(tmp_path, capsys):
    import sqlite3

    out = tmp_path / "o"
    out.mkdir()
    (out / "config.json").write_text('{"suite": "tiny", "k": 1, "k": 2, "seed": 2026}')
    _store(out / "results.sqlite", 2)
    assert "key 'k' appears twice" in _one_line_error(capsys, ["report", str(out)])
    (out / "config.json").write_text('{"suite": "tiny", "k": 1, "seed": 2026}')
    (out / "results.sqlite").unlink()
    with sqlite3.connect(out / "results.sqlite") as db:
        db.execute("CREATE TABLE notes (x TEXT)")
    before = (out / "results.sqlite").read_bytes()
    assert "no episodes table (tables: notes)" in _one_line_error(capsys, ["report", str(out)])
    assert (out / "results.sqlite").read_bytes() == before


@pytest.mark.parametrize("command", [["evaluate", "--quiet"], ["convert-routes", "tiny"]])
def test_an_empty_out_is_refused(capsys, command):
    assert "--out: is empty" in _one_line_error(capsys, [*command, "--out", ""])


@pytest.mark.parametrize("raising", ["raise KeyboardInterrupt", "class Boom(BaseException):\n    pass\n"
                                     "raise Boom('x')", "import sys\nsys.exit(3)"])
def test_agent_modules_that_raise_anything_at_import_are_one_line(tmp_path, capsys, raising):
    (tmp_path / "bad_agent.py").write_text(raising + "\n")
    line = _one_line_error(capsys, ["evaluate", "--agent", f"{tmp_path / 'bad_agent.py'}:A",
                                    "--out", str(tmp_path / "o"), "--quiet"])
    assert "cannot import" in line and not (tmp_path / "o").exists()


def test_huge_actions_are_refused():
    import numpy as np

    from icrsumo.agents.base import MAX_WAYPOINTS, Action, AgentError, validate_action

    with pytest.raises(AgentError, match=f"at most {MAX_WAYPOINTS} waypoints, got 1000000"):
        validate_action(Action(waypoints=np.ones((10**6, 2))))


def test_a_folder_where_an_output_file_belongs_is_one_line(tmp_path, capsys):
    out = tmp_path / "o"
    out.mkdir()
    _store(out / "results.sqlite", 3)
    (out / "config.json").write_text('{"suite": "tiny", "k": 1, "seed": 2026, "scoring": "lb1"}')
    (out / "summary.json").mkdir()
    code = main(["report", str(out), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and "Traceback" not in "".join(err)
    assert err[-1].startswith(f"icrsumo: error: {out / 'summary.json'}: Is a directory (fix: check the path")


def test_the_last_resort_is_one_line_and_debug_shows_the_traceback(tmp_path, capsys, monkeypatch):
    import icrsumo.evaluation.run as run

    def boom(out, quiet=False, scoring=None):
        raise KeyError("something nobody foresaw")

    monkeypatch.setattr(run, "report_only", boom)
    monkeypatch.setattr("icrsumo.evaluation.report_only", boom)
    line = _one_line_error(capsys, ["report", str(tmp_path)])
    assert line.startswith("icrsumo: error: KeyError") and "--debug" in line
    with pytest.raises(KeyError):
        main(["report", str(tmp_path), "--debug"])


# ------------------------------------------------------------------ with SUMO
def _opts(out, suite, **kw) -> EvalOptions:
    base = dict(out=out, suite=str(suite), agents=(f"{AGENTS}:Cruise",), families=("noise",), k=1,
                workers=1, quiet=True)
    base.update(kw)
    return EvalOptions(**base)


@pytest.mark.sumo
def test_agent_code_that_exits_is_a_crash_in_process(suite, tmp_path):
    res = run_evaluation(_opts(tmp_path / "o", suite, agents=(f"{AGENTS}:Exits", f"{AGENTS}:Interrupts",
                                                              f"{AGENTS}:RaisesBase"), agent_timeout=None))
    assert (res.done, res.crashed) == (0, 6)
    with ResultStore(tmp_path / "o" / "results.sqlite") as s:
        msgs = {r.agent: r.message for r in s.records()}
    assert msgs["exits"].startswith("SystemExit: 0 at user_agents.py")
    assert msgs["interrupts"].startswith("KeyboardInterrupt")
    assert msgs["raises-base"].startswith("Boom: not an Exception")
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["episodes"]["crashed"] == 6


@pytest.mark.sumo
def test_retry_crashed_repairs_a_transient_fault_in_place(suite, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    Path("flaky.marker").write_text("down")
    argv = ["evaluate", "--suite", str(suite), "--agent", f"{AGENTS}:Flaky", "--family", "noise", "--k", "1",
            "--workers", "1", "--quiet", "--out", "o"]
    assert main(argv) == 0
    assert "2 crashed (left out of every table, with their pairs; --retry-crashed" in capsys.readouterr().err
    md = Path("o/results.md").read_text(encoding="utf-8")
    assert "| flaky | baseline | — | — | — | — | — | — | — | — | — | 0 | 1 |" in md
    assert "2 episodes crashed and are left out" in md
    assert main([*argv, "--fail-on-crash"]) == 1  # for CI: a run with crashes fails
    os.remove("flaky.marker")
    assert main(argv) == 0  # a plain rerun keeps the crashes
    assert "0 episodes done, 2 crashed" in capsys.readouterr().err
    assert main([*argv, "--retry-crashed", "--fail-on-crash"]) == 0
    assert "2 episodes done, 0 crashed" in capsys.readouterr().err
    assert "crashed and" not in Path("o/results.md").read_text(encoding="utf-8")
    with ResultStore(tmp_path / "o" / "results.sqlite") as s:
        assert {r.status for r in s.records()} == {"done"}


@pytest.mark.sumo
@pytest.mark.parametrize("flag", [["--rollout-route", "nowhere"], ["--routes", "nowhere"]])
def test_a_refused_run_leaves_no_folder_and_no_config(suite, tmp_path, capsys, flag):
    argv = ["evaluate", "--suite", str(suite), "--agent", "route-oracle", "--k", "1", "--quiet", *flag]
    assert "nowhere" in _one_line_error(capsys, [*argv, "--out", str(tmp_path / "new")])
    assert not (tmp_path / "new").exists()
    (tmp_path / "empty").mkdir()
    _one_line_error(capsys, [*argv, "--out", str(tmp_path / "empty")])
    assert list((tmp_path / "empty").iterdir()) == []


@pytest.mark.sumo
def test_a_stored_route_that_cannot_be_reloaded_is_an_error_not_a_gap(suite, tmp_path, capsys):
    own = tmp_path / "suite"
    shutil.copytree(suite, own)
    opts = _opts(tmp_path / "o", own, agents=("route-oracle",))
    first = run_evaluation(opts).stats
    manifest = next(own.glob("scenarios/*/scenario.json"))
    doc = json.loads(manifest.read_text())
    doc["net"] = doc["net"].replace(".net.xml", "_gone.net.xml")
    manifest.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="holds 2 stored episodes, but the route cannot be loaded"):
        run_evaluation(opts)
    capsys.readouterr()
    again = report_only(tmp_path / "o", quiet=True)  # the stored numbers, from the store alone
    assert again.episodes == first.episodes == EpisodeCounts(done=2, crashed=0)


@pytest.mark.sumo
def test_stored_episodes_outside_the_selection_are_counted(suite, tmp_path, capsys):
    out = tmp_path / "o"
    run_evaluation(_opts(out, suite, agents=("route-oracle",)))
    summary = run_evaluation(_opts(out, suite, agents=("instruction-follower",))).summary
    assert summary["episodes"]["stored_not_in_report"] == 2
    assert "2 stored episodes are not in this report: they are of other agents" in capsys.readouterr().err


@pytest.mark.sumo
def test_control_families_run_beside_the_others_and_the_oracle_ignores_them(suite, tmp_path):
    res = run_evaluation(_opts(tmp_path / "o", suite, agents=("route-oracle",),
                               families=("noise", "blank", "shuffled"), k=2))
    assert res.episodes == 1 + 2 + 1 + 2  # baseline, noise x2, blank x1, shuffled x2
    fams = res.summary["agents"]["route-oracle"]["families"]
    assert list(fams) == ["noise", "blank", "shuffled"]
    assert all(fams[f]["dDS"] == 0.0 and fams[f]["dRC"] == 0.0 for f in fams)


@pytest.mark.sumo
def test_a_damaged_stored_log_leaves_the_tables_whole(suite, tmp_path, capsys):
    import sqlite3

    out = tmp_path / "o"
    run_evaluation(_opts(out, suite, agents=("route-oracle",), rollout_route=None))
    with sqlite3.connect(out / "results.sqlite") as db:
        db.execute("UPDATE episodes SET log = x'00010203' WHERE family = 'noise'")
    capsys.readouterr()
    assert main(["report", str(out), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "1 stored episode logs cannot be read" in err and "its stored log is damaged" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["episodes"] == {"done": 2, "crashed": 0}
    assert summary["agents"]["route-oracle"]["families"]["noise"]["decisions"]["followed_route"] == 0


def test_a_name_property_on_the_class_is_no_name():
    from icrsumo.agents.registry import agent_name

    class Named:
        @property
        def name(self):
            return "dynamic"

    assert agent_name("mod.py:Named", Named) == "mod.py:Named"
    assert agent_name("x", type("A", (), {"name": "cruise"})) == "cruise"
    assert agent_name("x", type("A", (), {"name": "  "})) == "x"


@pytest.mark.parametrize("argv, expect", [
    (["check-agent", "route-oracle", "--timeout", "nan"],
     "--timeout: nan: must be a positive number of seconds"),
    (["check-agent", "route-oracle", "--decisions", "0"], "--decisions: 0: must be at least 1"),
    (["convert-routes", "no-such-suite", "--out", "unused"],
     "routes: no-such-suite: unknown suite (fix: use a bundled suite"),
])
def test_each_bad_value_is_named(capsys, argv, expect):
    assert expect in _one_line_error(capsys, argv)


def test_report_names_what_is_missing(tmp_path, capsys):
    out = tmp_path / "o"
    out.mkdir()
    _store(out / "results.sqlite", 1)
    (out / "config.json").mkdir()
    line = _one_line_error(capsys, ["report", str(out)])
    assert f"{out / 'config.json'}: is a folder, not a file" in line
