"""icrsumo evaluate: paired protocol, store, resume after SIGKILL, backends, bad input."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
import zlib
from pathlib import Path

import pytest

from icrsumo.app.cli.main import main
from icrsumo.core.defaults import LOOP_VERSION
from icrsumo.evaluation import EvalOptions, run_evaluation
from icrsumo.evaluation.digests import DIGEST_RE, folder_digest
from icrsumo.results.store import ResultStore
from icrsumo.world.convert import CONVERTER_VERSION

pytestmark = pytest.mark.sumo

AGENTS = Path(__file__).parents[1] / "data" / "agents" / "user_agents.py"
ROUTES = ("tiny_003", "tiny_012")


def evaluate(opts: EvalOptions) -> dict:
    """Run an evaluation; its summary."""
    return run_evaluation(opts).summary


def _opts(out, **kw):
    base = dict(out=out, suite="tiny", agents=("route-oracle", "instruction-follower"),
                families=("misleading", "noise"), k=2, routes=ROUTES, workers=1, quiet=True)
    base.update(kw)
    return EvalOptions(**base)


def _records(out):
    with ResultStore(out / "results.sqlite") as s:
        return [(r.agent, r.route_id, r.family, r.k, r.status, r.ds, r.rc, r.is_, r.termination)
                for r in s.records()]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("ref")
    summary = evaluate(_opts(out))
    return out, summary


def test_reference_run_writes_everything(reference):
    out, summary = reference
    assert summary["episodes"] == {"done": 2 * 2 * 5, "crashed": 0}
    for name in ("summary.json", "results.md", "results.csv", "results.tex", "episodes.csv",
                 "figures/rd_to.png", "figures/delta_bars.png"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    assert list((out / "figures").glob("rollout_*.png"))
    assert list((out / "leaderboard").glob("*.json"))
    s = json.loads((out / "summary.json").read_text())
    fam = s["agents"]["instruction-follower"]["families"]["misleading"]
    assert set(fam) >= {"DS", "RC", "IS", "dDS", "dRC", "dIS", "worst_dDS", "dDS_ci95", "dRC_ci95",
                        "RD", "TO"}
    assert fam["dRC"] < 0 and s["agents"]["route-oracle"]["families"]["misleading"]["dDS"] == 0


def test_workers_and_rerun_give_identical_results(reference, tmp_path):
    ref_out, _ = reference
    evaluate(_opts(tmp_path, workers=2))
    assert (tmp_path / "summary.json").read_bytes() == (ref_out / "summary.json").read_bytes()
    # so is the digest in it (every stored episode's log), and it is the store's
    digest = json.loads((tmp_path / "summary.json").read_text())["digest"]
    assert DIGEST_RE.fullmatch(digest) and folder_digest(tmp_path).digest == digest
    assert _records(tmp_path) == _records(ref_out)
    # a rerun resumes: nothing left to do, same outputs
    before = (tmp_path / "results.sqlite").stat().st_size
    evaluate(_opts(tmp_path, workers=2))
    assert (tmp_path / "summary.json").read_bytes() == (ref_out / "summary.json").read_bytes()
    assert (tmp_path / "results.sqlite").stat().st_size >= before


def test_the_digest_is_the_stores_and_names_a_changed_episode(reference, tmp_path, capsys):
    """summary.json's digest is what `icrsumo digest OUT` computes from the store; a copy of the
    folder is the same, and one stored log edited in it makes `digest A B` name that episode."""
    ref_out, summary = reference
    capsys.readouterr()
    assert main(["digest", str(ref_out)]) == 0
    got = capsys.readouterr()
    assert got.out == f"{summary['digest']}\n" and "20 stored episodes, scoring lb1" in got.err
    assert "summary.json holds the same digest" in got.err
    copy = tmp_path / "copy"
    copy.mkdir()
    for name in ("config.json", "results.sqlite", "summary.json"):
        (copy / name).write_bytes((ref_out / name).read_bytes())
    assert main(["digest", str(ref_out), str(copy)]) == 0
    assert capsys.readouterr().out.splitlines()[0] == "same"
    key = ("instruction-follower", "tiny_012", "noise", 1, 2026)
    where = "WHERE agent=? AND route_id=? AND family=? AND k=? AND seed=?"
    with sqlite3.connect(copy / "results.sqlite") as db:
        text = zlib.decompress(db.execute(f"SELECT log FROM episodes {where}", key).fetchone()[0]).decode()
        db.execute(f"UPDATE episodes SET log=? {where}", (zlib.compress(text.replace("]", " ]", 1).encode()),
                                                          *key))
    assert main(["digest", str(ref_out), str(copy)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "differs" and out[-1] == ("  first difference: episode instruction-follower/tiny_012/"
                                               "noise/1/2026: its stored logs differ")
    assert main(["digest", str(copy)]) == 0
    assert "summary.json: digest sha256:" in capsys.readouterr().err  # the stored one no longer agrees


def test_report_rebuilds_without_simulating(reference, tmp_path, capsys):
    ref_out, _ = reference
    summary = (ref_out / "summary.json").read_bytes()
    (ref_out / "summary.json").unlink()
    assert main(["report", str(ref_out), "--quiet"]) == 0
    assert (ref_out / "summary.json").read_bytes() == summary


def test_report_rescores_from_the_logs_alone_to_the_same_numbers(reference, tmp_path, capsys):
    """`report --scoring lb1` scores every stored episode again from its log (no simulation):
    the same records, the same summary and tables as the run that stored them; the episodes'
    terminations replay from their logs to the same kind and time."""
    from icrsumo.scoring.criteria import replay
    from icrsumo.scoring.lb1 import LB1_RULES

    ref_out, _ = reference
    copy = tmp_path / "copy"
    copy.mkdir()
    for name in ("config.json", "results.sqlite"):
        (copy / name).write_bytes((ref_out / name).read_bytes())
    (copy / "instructions").symlink_to(ref_out / "instructions")
    # the routes' key points (the results files' route lengths) come from the folder's scenarios
    (copy / "scenarios").symlink_to(ref_out / "scenarios")
    assert main(["report", str(copy), "--quiet", "--scoring", "lb1"]) == 0
    for name in ("summary.json", "results.md", "episodes.csv", "leaderboard/route-oracle_misleading.json"):
        assert (copy / name).read_bytes() == (ref_out / name).read_bytes(), name
    assert json.loads((copy / "summary.json").read_text())["scoring"] == "lb1"
    with ResultStore(ref_out / "results.sqlite") as store:
        for r in store.records():
            log = store.episode_log(r.agent, r.route_id, r.family, r.k, r.seed)
            assert replay(log, LB1_RULES) == (log.termination, log.termination_t)
    code = main(["report", str(copy), "--quiet", "--scoring", "lb9"])
    assert code == 2 and "--scoring" in capsys.readouterr().err


def test_a_run_under_one_scoring_rescores_to_a_fresh_run_under_the_other(tmp_path):
    """An lb2 run rescored with lb1 gives the episodes of a fresh lb1 run (its logs are cut
    exactly where 1.0's rules end them), and rescored with lb2 its own files."""
    two, one = tmp_path / "lb2", tmp_path / "lb1"
    kw = dict(agents=("route-oracle", "instruction-follower"), families=("misleading",), k=1,
              routes=("tiny_003",))
    evaluate(_opts(two, scoring="lb2", **kw))
    assert json.loads((two / "config.json").read_text())["scoring"] == "lb2"
    status = json.loads((two / "leaderboard" / "route-oracle_baseline.json").read_text())
    assert status["_checkpoint"]["records"][0]["status"] in ("Perfect", "Completed")
    evaluate(_opts(one, **kw))
    copy = tmp_path / "copy"
    copy.mkdir()
    for name in ("config.json", "results.sqlite"):
        (copy / name).write_bytes((two / name).read_bytes())
    (copy / "instructions").symlink_to(two / "instructions")
    assert main(["report", str(copy), "--quiet", "--scoring", "lb2"]) == 0
    assert (copy / "summary.json").read_bytes() == (two / "summary.json").read_bytes()
    assert main(["report", str(copy), "--quiet", "--scoring", "lb1"]) == 0
    assert (copy / "episodes.csv").read_bytes() == (one / "episodes.csv").read_bytes()


def test_stored_episodes_agree_with_the_leaderboard_transcription(reference):
    """Every stored episode's DS, RC and IS, rescored from its log by the leaderboard's code
    transcribed in tests/lb1_reference.py, agree with the stored ones within 1e-4."""
    import lb1_reference

    ref_out, _ = reference
    with ResultStore(ref_out / "results.sqlite") as store:
        records = store.records()
        assert records
        for r in records:
            got = lb1_reference.score(store.episode_log(r.agent, r.route_id, r.family, r.k, r.seed))
            assert abs(got["score_route"] - r.rc) <= 1e-4 and abs(got["score_penalty"] - r.is_) <= 1e-4
            assert abs(got["score_composed"] - r.ds) <= 1e-4
            assert got["ended"] in (str(r.termination), None)


def test_results_files_agree_with_the_leaderboard_transcription(reference):
    """tools/check_lb1.py: the stored episodes, and every leaderboard/<agent>_<family>.json
    against the file tests/lb1_reference.py builds from the same records and the routes' key
    points (their lengths, not the lanes')."""
    ref_out, _ = reference
    tool = Path(__file__).parents[2] / "tools" / "check_lb1.py"
    proc = subprocess.run([sys.executable, str(tool), str(ref_out)], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "6 results files (16 routes with key points); 0 differ" in proc.stdout
    cp = json.loads((ref_out / "leaderboard" / "instruction-follower_noise.json").read_text())
    lengths = {r["route_id"]: r["meta"]["route_length"] for r in cp["_checkpoint"]["records"]}
    with ResultStore(ref_out / "results.sqlite") as store:
        lanes = {f"RouteScenario_{r.route_id}_noise_{r.k}": r.length for r in store.records()}
    assert all(0 < lengths[k] < lanes[k] for k in lengths)  # straight lines between waypoints


def test_another_scoring_is_another_configuration(reference, capsys):
    ref_out, _ = reference
    raw = (ref_out / "config.json").read_bytes()
    cfg = json.loads(raw)
    assert cfg["scoring"] == "lb1"
    (ref_out / "config.json").write_text(json.dumps({**cfg, "scoring": None}))
    try:
        code = main(["evaluate", "--out", str(ref_out), "--routes", ",".join(ROUTES), "--k", "2",
                     "--agent", "route-oracle", "--agent", "instruction-follower", "--family", "misleading",
                     "--family", "noise", "--quiet"])
        err = capsys.readouterr().err
        assert code == 2 and "scored before icrsumo scored by the leaderboard's own rules" in err
        assert main(["report", str(ref_out), "--quiet"]) == 2
        assert "scored before" in capsys.readouterr().err
    finally:
        (ref_out / "config.json").write_bytes(raw)


@pytest.mark.parametrize(("key", "now", "said"), [
    # scenarios of an earlier converter (before the background fleet was capped, or before
    # background drivers grew impatient) hold other traffic
    ("converter", CONVERTER_VERSION, ("converted by an earlier icrsumo", "another --out")),
    # episodes of the loop's first rules (roadside once per exit, red light at the junction entry)
    ("loop", LOOP_VERSION, (f"loop=1 (now {LOOP_VERSION})", "earlier rules", "another --out")),
])
def test_a_folder_of_an_earlier_converter_or_loop_is_not_resumed(reference, capsys, key, now, said):
    """New episodes would not pair with the stored ones: the run is refused in one line; the
    stored results still report."""
    ref_out, _ = reference
    raw = (ref_out / "config.json").read_bytes()
    cfg = json.loads(raw)
    assert cfg[key] == now
    (ref_out / "config.json").write_text(json.dumps({k: v for k, v in cfg.items() if k != key}))
    try:
        code = main(["evaluate", "--out", str(ref_out), "--routes", ",".join(ROUTES), "--k", "2",
                     "--agent", "route-oracle", "--agent", "instruction-follower", "--family", "misleading",
                     "--family", "noise", "--quiet"])
        err = capsys.readouterr().err
        assert code == 2 and all(words in err for words in said), err
        assert main(["report", str(ref_out), "--quiet"]) == 0  # stored results still report
    finally:
        (ref_out / "config.json").write_bytes(raw)


def test_ray_backend_gives_identical_results(reference, tmp_path, monkeypatch):
    """... on a private local cluster of its own: a RAY_ADDRESS (or a leftover session file)
    pointing at a cluster that is gone is not joined."""
    pytest.importorskip("ray")
    ref_out, _ = reference
    monkeypatch.setenv("RAY_ADDRESS", "127.0.0.1:1")
    evaluate(_opts(tmp_path, backend="ray", workers=2))
    assert _records(tmp_path) == _records(ref_out)
    assert (tmp_path / "summary.json").read_bytes() == (ref_out / "summary.json").read_bytes()


def test_sigkill_then_resume(reference, tmp_path, capsys):
    ref_out, _ = reference
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "icrsumo", "evaluate", "--suite", "tiny", "--agent", "route-oracle",
           "--agent", "instruction-follower", "--family", "misleading", "--family", "noise", "--k", "2",
           "--routes", ",".join(ROUTES), "--workers", "2", "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    db = out / "results.sqlite"
    deadline = time.time() + 240
    n = 0
    while time.time() < deadline and proc.poll() is None:
        if db.is_file():
            try:
                with sqlite3.connect(db) as c:
                    n = c.execute("SELECT COUNT(*) FROM episodes").fetchone()[0]
            except sqlite3.Error:
                n = 0
            if n >= 5:
                break
        time.sleep(0.2)
    assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    with sqlite3.connect(db) as c:
        killed_at = c.execute("SELECT COUNT(*) FROM episodes").fetchone()[0]
    assert 5 <= killed_at < 20
    capsys.readouterr()
    assert main(cmd[3:]) == 0
    with sqlite3.connect(db) as c:
        keys = c.execute("SELECT agent, route_id, family, k, seed FROM episodes").fetchall()
    assert len(keys) == len(set(keys)) == 20
    assert _records(out) == _records(ref_out)
    assert (out / "summary.json").read_bytes() == (ref_out / "summary.json").read_bytes()
    # the run's last line: its digest, the reference run's (same episodes, however they were run)
    last = capsys.readouterr().err.splitlines()[-1]
    digest = reference[1]["digest"]
    assert last == f"digest: {digest} (same digest on another machine = every episode the same)"


def test_crashing_agent_is_retried_then_stored(tmp_path, capsys):
    spec = f"{AGENTS}:Raises"
    summary = evaluate(_opts(tmp_path, agents=(spec, f"{AGENTS}:Cruise"), routes=("tiny_003",),
                             families=("misleading",), k=1))
    assert summary["episodes"] == {"done": 2, "crashed": 2}
    with ResultStore(tmp_path / "results.sqlite") as s:
        crashed = [r for r in s.records() if r.status == "crashed"]
    assert {r.agent for r in crashed} == {"raises"}
    assert all(r.attempts == 2 and "agent exploded" in r.message for r in crashed)


@pytest.mark.parametrize("argv, expect", [
    (["--agent", "no-such-agent"], "not a built-in agent"),
    (["--agent", f"{AGENTS}:NoAct"], "does not implement the agent protocol (missing act)"),
    (["--agent", "no_such_module_xyz:Agent"], "cannot import no_such_module_xyz"),
    (["--family", "sarcasm"], "unknown family"),
    (["--suite", "huge"], "unknown suite"),
    (["--backend", "slurm"], "unknown backend"),
])
def test_bad_input_is_one_line_and_touches_nothing(tmp_path, capsys, argv, expect):
    out = tmp_path / "o"
    code = main(["evaluate", "--out", str(out), "--quiet", *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and expect in err[0] and "Traceback" not in err[0]
    assert not out.exists()


def test_other_configuration_is_refused(reference, capsys):
    ref_out, _ = reference
    before = {p: p.read_bytes() for p in ref_out.rglob("*") if p.is_file()}
    code = main(["evaluate", "--out", str(ref_out), "--seed", "7", "--routes", ",".join(ROUTES), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "different configuration" in err and "seed=2026" in err
    assert {p: p.read_bytes() for p in ref_out.rglob("*") if p.is_file()} == before


def test_broken_actions_are_crashes_with_reasons(tmp_path):
    summary = evaluate(_opts(tmp_path, agents=(f"{AGENTS}:NaNs", f"{AGENTS}:WrongShape"),
                             routes=("tiny_003",), families=("noise",), k=1))
    assert summary["episodes"] == {"done": 0, "crashed": 4}
    with ResultStore(tmp_path / "results.sqlite") as s:
        msgs = {r.agent: r.message for r in s.records()}
    assert "waypoints contain NaN" in msgs["nans"]
    assert "waypoints must have shape (N, 2)" in msgs["wrong-shape"] and "(3,)" in msgs["wrong-shape"]
