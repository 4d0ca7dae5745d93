"""tools/batched_inference.py runs end to end on CPU with synthetic frames (serve-agent with
batching and in-process workers) and ends with one JSON line; its replay loader reads a
recorded-episode file (no timing assertions: timings depend on the machine)."""

from __future__ import annotations

import importlib.util
import json
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.sumo

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "tools" / "batched_inference.py"


def _module():
    spec = importlib.util.spec_from_file_location("batched_inference", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_frames_synthetic_and_replayed(tmp_path):
    bi = _module()
    ep = bi.synthetic_episode(0)
    assert ep["bev"].shape[1:] == (7, 128, 128) and ep["bev"].dtype == np.uint8
    assert set(np.unique(ep["bev"])) == {0, 255} and len(ep["speed"]) == len(ep["texts"]) == len(ep["bev"])
    # a recorded episode as icrsumo.learn.collect writes it: bit-packed bev, instruction indices
    raster = ep["bev"][:5]
    instructions = [{"id": 0, "text": "Keep following the road."}, {"id": 1, "text": "Turn left."}]
    path = tmp_path / "ep.npz"
    np.savez(path, bev=np.packbits(raster > 0, axis=-1), speed=np.arange(5, dtype=np.float32),
             instruction=np.array([-1, 0, 0, 1, 1], np.int16),
             instructions=np.array(json.dumps(instructions)))
    rep = bi.load_episode([str(path)], 0, 300)
    assert np.array_equal(rep["bev"], raster)
    keep = "Keep following the road."
    assert rep["texts"] == ["", keep, keep, "Turn left.", "Turn left."]
    obs = bi.observations(rep)
    next(obs)
    second = next(obs)
    assert second.t == 0.1 and np.array_equal(second.bev, raster[1]) and second.speed == 1.0


def test_script_runs_on_cpu_with_synthetic_frames(tmp_path):
    db = tmp_path / "results.sqlite"
    con = sqlite3.connect(db)
    con.execute("CREATE TABLE episodes (status TEXT, duration REAL)")
    con.executemany("INSERT INTO episodes VALUES (?, ?)", [("done", 10.0), ("done", 20.0), ("crashed", None)])
    con.commit()
    con.close()
    out = tmp_path / "bi.json"
    proc = subprocess.run(
        [sys.executable, str(SCRIPT), "--clients", "2", "--modes", "batched,inprocess-cpu", "--device", "cpu",
         "--seconds", "0.2", "--warmup", "1", "--sim-ms", "0.5", "--results-db", str(db), "--json", str(out)],
        capture_output=True, text=True, timeout=120, cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    assert res == json.loads(out.read_text())
    assert "| batched | cpu | 16 |" in proc.stdout and "| inprocess-cpu | cpu |" in proc.stdout
    assert res["frames"] == "synthetic"
    assert res["acts_per_episode"] == pytest.approx(151.0)  # mean 15 s / 0.1 s + 1
    batched, cpu = res["modes"]["batched"], res["modes"]["inprocess-cpu"]
    for m in (batched, cpu):
        assert m["acts_per_s"]["median"] > 0 and m["clients"] == 2
        assert m["episodes_per_s"]["median"] == pytest.approx(m["acts_per_s"]["median"] / 151.0)
    assert batched["max_batch"] == 16 and 1.0 <= batched["mean_batch"]["median"] <= 2.0
    assert cpu["speedup_vs_inprocess_cpu"] == 1.0
