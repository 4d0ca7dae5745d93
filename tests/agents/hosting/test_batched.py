"""`icrsumo evaluate --batch-inference`: one real inference process per agent, fed by the
episode workers over a Unix socket (icrsumo.agents.hosting.batched)."""

from __future__ import annotations

import json
import pickle
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from icrsumo.agents.base import AgentError, EpisodeInfo, Observation
from icrsumo.agents.hosting.batched import BatchedFactory, start_server
from icrsumo.agents.registry import make_agent
from icrsumo.app.cli.main import main
from icrsumo.core.errors import InputError
from icrsumo.evaluation import EvalOptions, run_evaluation

pytestmark = pytest.mark.sumo

INFO = EpisodeInfo("r", "town", "net.xml", 0.05, 0.1, 7)


def _obs(t: float, text: str) -> Observation:
    bev = np.zeros((7, 128, 128), np.uint8)
    bev[0, 30:128, 48:80] = 255
    bev[1, :, 63:65] = 255
    return Observation(t=t, bev=bev, speed=2.5 + t % 1.0, instruction=text, instruction_id=0, notice="")


def _rows(out: Path) -> list[tuple]:
    with sqlite3.connect(out / "results.sqlite") as c:
        return c.execute("SELECT * FROM episodes ORDER BY agent, route_id, family, k, seed").fetchall()


def test_batched_cpu_evaluation_is_the_in_process_one(suite, tmp_path, capsys):
    """A learned agent through one CPU inference process (2 workers batching into it) and a
    privileged agent alongside (run by the workers as usual): stored episodes, logs and
    summary.json byte-identical to the plain run."""
    opts = dict(suite=str(suite), agents=("bev-ngram", "route-oracle"), families=("misleading",), k=2,
                workers=2)
    plain = run_evaluation(EvalOptions(out=tmp_path / "plain", quiet=True, **opts))
    batched = run_evaluation(EvalOptions(out=tmp_path / "batched", batch_inference="cpu", max_batch=4,
                                         inference_processes=2, **opts))
    err = capsys.readouterr().err
    assert "batched inference of bev-ngram on cpu (2 processes):" in err and "route-oracle on cpu" not in err
    # the inference processes' statistics come back in the result (none without batch_inference)
    assert plain.inference == {} and set(batched.inference) == {"bev-ngram"}
    stats = batched.inference["bev-ngram"]
    assert stats["processes"] == 2 and stats["resets"] == 3 and stats["acts"] > 0
    assert 1 <= stats["largest_batch"] <= 4 and stats["batches"] <= stats["acts"]
    rows = _rows(tmp_path / "plain")
    assert len(rows) == 6 and all("done" in r for r in rows)
    assert _rows(tmp_path / "batched") == rows
    assert (tmp_path / "batched" / "summary.json").read_bytes() == \
        (tmp_path / "plain" / "summary.json").read_bytes()


def test_client_matches_agent_and_reports_a_dead_server():
    server = start_server("bev-ngram", "cpu", max_batch=8)
    try:
        factory = BatchedFactory([server.address], server.name, server.key)
        remote, local = factory(), make_agent("bev-ngram")
        for agent in (remote, local):
            agent.reset(INFO)
        texts = ["Turn left at the next intersection.", "In 30 meters, go straight."]
        for i in range(6):
            obs = _obs(20.0 + 0.1 * i, texts[i % 2])
            a, b = remote.act(obs), local.act(obs)
            assert np.array_equal(a.waypoints, b.waypoints) and a.target_speed == b.target_speed
        # the factory travels pickled inside jobs: the key goes with it, its connection does not
        assert len(factory._conns) == 1
        clone = pickle.loads(pickle.dumps(factory))
        assert clone == factory and hash(clone) == hash(factory) and clone._conns == {}
        assert clone.key == server.key
        remote.close()
        with pytest.raises(AgentError, match="act\\(\\) before reset"):
            remote.act(_obs(21.0, texts[0]))
        server.proc.kill()
        server.proc.join()
        with pytest.raises(AgentError, match="batched inference process of bev-ngram is not answering"):
            remote.reset(INFO)
    finally:
        stats = server.stop()
    assert stats == {} or stats["acts"] == 6


def test_bad_batch_inference_options(suite, tmp_path, capsys):
    with pytest.raises(InputError, match="must be at least 1"):
        EvalOptions(out=tmp_path, suite=str(suite), batch_inference="cpu", inference_processes=0).check()
    with pytest.raises(InputError, match="local backend only"):
        EvalOptions(out=tmp_path, suite=str(suite), backend="ray", batch_inference="cpu").check()
    with pytest.raises(InputError, match="privileged agent"):
        start_server("route-oracle", "cpu")
    if not __import__("torch").cuda.is_available():
        code = main(["evaluate", "--suite", str(suite), "--agent", "bev-ngram", "--family", "noise",
                     "--k", "1", "--batch-inference", "cuda", "--out", str(tmp_path / "o"), "--quiet"])
        err = capsys.readouterr().err
        assert code == 2 and "no CUDA device" in err and "Traceback" not in err
        assert len(err.strip().splitlines()) == 1
        assert not (tmp_path / "o" / "results.sqlite").exists() or _rows(tmp_path / "o") == []


def test_closed_loop_script_runs_on_cpu(suite, tmp_path):
    """tools/batched_closed_loop.py end to end on CPU (in-process, the inference process and
    serve-agent): the same episodes in every setup, one JSON line (no timing assertions)."""
    script = Path(__file__).resolve().parents[3] / "tools" / "batched_closed_loop.py"
    proc = subprocess.run(
        [sys.executable, str(script), "--suite-dir", str(suite), "--agent", "bev-token", "--workers", "2",
         "--device", "cpu", "--families", "noise", "--k", "1", "--routes", "tiny_003",
         "--modes", "inprocess-cpu,ipc,batched@1",
         "--work", str(tmp_path / "w")], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    modes = res["modes"]
    assert set(modes) == {"inprocess-cpu", "ipc", "batched@1"}
    assert all(m["episodes"] == 2 and m["crashed"] == 0 and m["same_as_cpu"] == 2 for m in modes.values())
    assert modes["batched@1"]["workers"] == 1 and modes["ipc"]["mean_batch"]["median"] >= 1.0
    assert "| ipc | 2 | 2 |" in proc.stdout


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="abstract sockets are Linux's")
def test_a_killed_run_leaves_no_socket_folder_behind(tmp_path):
    """The inference process listens on an abstract socket: a run killed with SIGKILL (no
    finalizer runs) leaves nothing in the temporary folder."""
    import os
    import signal

    code = ("import sys, os; from icrsumo.agents.hosting.batched import start_server\n"
            "s = start_server('bev-ngram', 'cpu', max_batch=4)\n"
            "print(repr(s.address), flush=True); os.kill(os.getpid(), 9)\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "TMPDIR": str(tmp_path)})
    assert proc.returncode == -signal.SIGKILL, proc.stderr[-2000:]
    assert proc.stdout.startswith("'\\x00icrsumo-batch-")
    assert list(tmp_path.iterdir()) == []
