"""tools/benchmark.py --protocol on one route of LangAuto-tiny with K = 1: one table of the three
runs (agent, route-oracle, bare SUMO) whose phases cover the workers' time, the ratios and the
histogram, and one JSON line (no timing assertions: timings depend on the machine)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from icrsumo.agents.registry import DEFAULT_AGENT
from icrsumo.core.vocab import Phase

ROOT = Path(__file__).resolve().parents[1]


def _bench(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    cmd = [sys.executable, str(ROOT / "tools" / "benchmark.py"), "--protocol", "langauto", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=900, cwd=cwd)


@pytest.mark.sumo
def test_protocol_section_on_one_route(tmp_path):
    out = tmp_path / "bench.json"
    proc = _bench("--suites", "langauto-tiny", "--routes", "1", "--k", "1", "--json", str(out), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    res = json.loads(proc.stdout.strip().splitlines()[-1])["protocol"]
    assert res == json.loads(out.read_text())["protocol"]
    assert res["suites"] == ["langauto-tiny"] and res["agent"] == DEFAULT_AGENT and res["cpu"]
    assert res["full_protocol"] is False
    runs = res["runs"]
    # baseline + 4 families x K = 1 on one route; bare SUMO steps the agent's episodes
    assert [runs[k]["episodes"] for k in ("agent", "oracle", "bare")] == [5, 5, 5]
    assert runs["bare"]["steps"] == runs["agent"]["steps"] > 500
    for name, r in runs.items():
        capacity = r["wall_s"] * r["workers"]
        assert math.isclose(sum(r["phases_s"].values()), capacity, rel_tol=1e-6), name
        assert abs(r["other_share"]) <= res["tolerance"] == 0.01, name
        assert r["phases_s"]["sumo_step"] > 0 and r["phases_s"]["sumo_start"] > 0, name
    assert runs["agent"]["phases_s"]["act"] > 0 and runs["agent"]["phases_s"]["bev"] > 0
    assert runs["bare"]["phases_s"]["act"] == 0 == runs["bare"]["phases_s"]["bev"]
    ratios = res["ratios"]
    assert "met" not in ratios["protocol_wall_s"]  # a subset is not the target's run
    for key in ("loop_per_step_over_bare", "agent_over_oracle"):
        assert ratios[key]["value"] > 0 and isinstance(ratios[key]["met"], bool)
    # the one table: a column per run, a row per phase; the ratios; the histogram
    text = proc.stdout
    assert f"| | {DEFAULT_AGENT} | route-oracle | bare SUMO" in text
    phase_rows = [line for line in text.splitlines() if ", worker-s |" in line]
    assert len(phase_rows) == len(Phase) and all(line.count("%)") == 3 for line in phase_rows)
    assert "| phases cover workers x wall (other within 1 %) | yes | yes | yes |" in text
    assert "ratios (issue 48), one run:" in text and "episode length (simulated s)" in text
    assert f"CPU {res['cpu']}" in text


@pytest.mark.parametrize(("args", "named"), [
    (("--suites", "langauto-tiny,nope"), "--suites: nope: not a bundled suite"),
    (("--routes", "0"), "--routes: 0: out of range"),
    (("--k", "65"), "--k: 65: out of range"),
    (("--agent", "nobody"), "nobody: not a built-in agent"),
])
def test_bad_options_are_one_line_before_anything_runs(tmp_path, args, named):
    proc = _bench(*args, "--json", str(tmp_path / "bench.json"), cwd=tmp_path)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and named in proc.stderr and "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == []
