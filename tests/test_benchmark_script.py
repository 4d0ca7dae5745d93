"""tools/benchmark.py runs end to end in its quick mode and ends with one JSON line (no timing
assertions: timings depend on the machine)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from icrsumo.agents.registry import DEFAULT_AGENT

pytestmark = pytest.mark.sumo

ROOT = Path(__file__).resolve().parents[1]


def test_quick_benchmark_prints_a_table_and_a_json_line(tmp_path):
    out = tmp_path / "bench.json"
    proc = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "benchmark.py"), "--quick", "--skip-eval",
         "--agents", f"route-oracle,{DEFAULT_AGENT},{DEFAULT_AGENT}-torch", "--repeats", "1",
         "--instr-routes", "20", "--json", str(out)],
        capture_output=True, text=True, timeout=300, cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.strip().splitlines()
    res = json.loads(lines[-1])
    assert res == json.loads(out.read_text())
    assert "| bare SUMO" in proc.stdout and "| route-oracle |" in proc.stdout
    cl = res["closed_loop"]
    assert set(cl["agents"]) == {"runner-only", "route-oracle", DEFAULT_AGENT, f"{DEFAULT_AGENT}-torch"}
    assert not cl["errors"]
    assert cl["runner_only_same_trajectory"] is True
    oracle = cl["agents"]["route-oracle"]
    assert oracle["termination"] == "completed" and oracle["steps"] > 100
    for key in ("bare_sumo_ms_per_step", "closed_loop_ms_per_step", "ratio_to_bare", "bev_ms_per_frame",
                "act_ms_per_call", "sim_s_per_wall_s"):
        assert oracle[key]["min"] <= oracle[key]["median"] <= oracle[key]["max"]
    assert res["instructions"]["variant_sets"] == 20 * 32
    assert "eval" not in res and res["targets"]["default_agent"] == DEFAULT_AGENT
    # the default agent in ONNX Runtime and in torch: the same route, both timed, targets checked
    for name in (DEFAULT_AGENT, f"{DEFAULT_AGENT}-torch"):
        assert cl["agents"][name]["termination"] == "completed"
        assert cl["agents"][name]["act_ms_per_call"]["median"] > 0
    for key in ("act_le_0_3_ms", "sim_rt_ge_100_per_core", "runner_le_0_25_ms_per_step"):
        assert isinstance(res["targets"][key]["met"], bool)
    assert res["targets"]["act_speedup_over_torch"]["value"] > 0
    assert "targets (issue 17):" in proc.stdout
