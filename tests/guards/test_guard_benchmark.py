"""tools/benchmark.py --guards: each guard's time per check and per episode and its blocks, on one
tiny route with K = 1, the checks per episode read from a real guarded evaluation, which the
benchmark leaves byte for byte as it was (no timing assertions: timings depend on the machine)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from icrsumo.app.api import evaluate
from icrsumo.guards.plan import PlanGuard
from icrsumo.guards.stream import GuardedStream, replay_checks
from icrsumo.instructions.store import read_instruction_sets
from icrsumo.results.store import ResultStore
from icrsumo.world.networks import load_net
from icrsumo.world.scenario import find_scenarios, read_scenario

pytestmark = pytest.mark.sumo

ROOT = Path(__file__).resolve().parents[2]
ROUTE = "tiny_003"


def _bench(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "tools" / "benchmark.py"), "--guards", *args],
                          capture_output=True, text=True, timeout=600, cwd=tmp_path)


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_guard_timing_per_check_and_per_episode_from_a_stored_run(tmp_path):
    run = tmp_path / "run"
    evaluate(agents="instruction-follower", guards="plan", families="misleading", k=1, routes=[ROUTE],
             out=run, workers=1, quiet=True)
    before = _files(run)
    out = tmp_path / "bench.json"
    proc = _bench(tmp_path, "--guard", "plan", "--guard", "text", "--guard-routes", ROUTE, "--guard-k", "1",
                  "--guard-run", str(run), "--json", str(out))
    assert proc.returncode == 0, proc.stderr[-3000:]
    res = json.loads(proc.stdout.strip().splitlines()[-1])["guards"]
    assert res == json.loads(out.read_text())["guards"]
    assert res["cpu"] and res["sequences"] == 5 and set(res["guards"]) == {"plan", "text"}
    # the guarded row's baseline and misleading episodes, each checking the route's instructions
    cpe = res["checks_per_episode"]
    assert cpe["episodes"] == 2 and cpe["mean"] > 0 and set(cpe["families"]) == {"baseline", "misleading"}
    for name, r in res["guards"].items():
        c = r["check_s"]
        assert r["checks"] > 0 and 0 < c["median"] <= c["p90"], name
        assert r["episode_s"] == pytest.approx(cpe["mean"] * c["median"]), name
        assert r["false_blocks"]["checked"] > 0 and r["false_blocks"]["blocked"] == 0, name
    mis = res["guards"]["plan"]["blocked"]
    assert sum(mis[f]["checked"] for f in ("misleading held-out", "misleading tuning") if f in mis) > 0
    assert "| plan |" in proc.stdout and "ms per check" in proc.stdout and res["cpu"] in proc.stdout
    # the replay checks what the closed loop checked, in the same order with the same verdicts,
    # on to the end of the route where an episode ended earlier
    sc = next(read_scenario(d) for d in find_scenarios(run / "scenarios") if d.name == ROUTE)
    for iset in read_instruction_sets(run / "instructions" / f"{ROUTE}.json"):
        if str(iset.family) not in ("baseline", "misleading") or iset.k:
            continue
        with ResultStore(run / "results.sqlite", readonly=True) as store:
            log = store.episode_log("instruction-follower+guard:plan", ROUTE, str(iset.family), 0, 2026)
        ins = iset.instructions
        decisions, seconds = replay_checks(GuardedStream(PlanGuard(), sc, load_net(sc.net), ins,
                                                         [i.rendered() for i in ins]))
        assert len(seconds) == len(decisions) == len({i.trigger for i in ins}) >= len(log.guard) > 0
        assert [(d.instruction_id, d.verdict) for d in decisions[:len(log.guard)]] \
            == [(d.instruction_id, d.verdict) for d in log.guard]
    after = _files(run)   # timings live in benchmark output only (SQLite's reader may leave its -shm file)
    assert {name: after.get(name) for name in before} == before
    assert set(after) - set(before) <= {"results.sqlite-shm", "results.sqlite-wal"}


@pytest.mark.parametrize(("args", "line"), [
    (("--guard", "nope"), "benchmark: guards: nope: unknown guard"),
    (("--guard", "plan", "--guard-routes", "tiny_999"), "benchmark: --guard-routes: tiny_999: no such route"),
    (("--guard", "plan", "--guard-run", "nowhere"), "benchmark: --guard-run: nowhere: holds no results")])
def test_bad_input_is_one_line_before_anything_is_timed(tmp_path, args, line):
    proc = _bench(tmp_path, *args)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.startswith(line) and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
