"""Remote agents under evaluate: every servable agent through a real `icrsumo serve-agent`
process on loopback gives the in-process results byte for byte; its errors and hangs are
crashes with reasons."""

from __future__ import annotations

import re
import sqlite3
import subprocess
import sys
import time
from contextlib import ExitStack, contextmanager
from pathlib import Path

import pytest

from icrsumo.agents.registry import BUILTIN
from icrsumo.evaluation import EvalOptions, run_evaluation
from icrsumo.results.store import ResultStore

pytestmark = pytest.mark.sumo

AGENTS = Path(__file__).parents[1] / "data" / "agents" / "user_agents.py"
#: non-privileged built-in agents (learned ones, once registered) are served and compared too
SERVABLE = [f"{AGENTS}:BevKeeper"] + sorted(n for n, c in BUILTIN.items()
                                            if not getattr(c, "privileged", True))


def evaluate(opts: EvalOptions) -> dict:
    return run_evaluation(opts).summary


@contextmanager
def served(spec: str, *extra: str):
    """A real `icrsumo serve-agent` process on a free loopback port: yields its URL."""
    proc = subprocess.Popen([sys.executable, "-m", "icrsumo", "serve-agent", spec, "--port", "0", *extra],
                            stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stderr.readline()
        m = re.search(r"on (http://127\.0\.0\.1:\d+) ", line)
        assert m, line + proc.stderr.read()[-2000:] if proc.poll() is not None else line
        yield m.group(1)
    finally:
        proc.terminate()
        proc.wait(timeout=20)


def _rows(out: Path) -> list[tuple]:
    with sqlite3.connect(out / "results.sqlite") as c:
        return c.execute("SELECT * FROM episodes ORDER BY agent, route_id, family, k, seed").fetchall()


def test_remote_agents_give_identical_results(suite, tmp_path):
    """Every servable agent (BevKeeper, which reads every observation field and offers act_batch,
    plus each non-privileged built-in, e.g. the learned ones) in-process and through its own
    serve-agent process: byte-identical stored episodes (scores and compressed logs) and
    summary.json, with parallel episodes batched."""
    opts = dict(suite=str(suite), families=("noise",), k=1, workers=2, quiet=True)
    t0 = time.perf_counter()
    evaluate(EvalOptions(out=tmp_path / "local", agents=tuple(SERVABLE), **opts))
    t_local = time.perf_counter() - t0
    with ExitStack() as stack:
        urls = [stack.enter_context(served(spec, "--max-batch", "4", "--device", "cpu")) for spec in SERVABLE]
        t0 = time.perf_counter()
        evaluate(EvalOptions(out=tmp_path / "remote", agents=tuple(f"remote:{u}" for u in urls), **opts))
        t_remote = time.perf_counter() - t0
    rows = _rows(tmp_path / "local")
    assert len(rows) == 2 * len(SERVABLE) and all("done" in r for r in rows)
    assert _rows(tmp_path / "remote") == rows
    summary = (tmp_path / "local" / "summary.json").read_bytes()
    assert (tmp_path / "remote" / "summary.json").read_bytes() == summary
    print(f"{len(SERVABLE)} agents: in-process {t_local:.1f} s, remote {t_remote:.1f} s")


def test_remote_agent_errors_are_crashes_with_reasons(suite, tmp_path):
    with served(f"{AGENTS}:NaNs") as nan_url, served(f"{AGENTS}:Hangs") as hang_url:
        agents = (f"remote:{nan_url}", f"remote:{hang_url}?timeout=1")
        summary = evaluate(EvalOptions(out=tmp_path, suite=str(suite), families=("noise",), k=1, workers=2,
                                       quiet=True, agents=agents))
    assert summary["episodes"] == {"done": 0, "crashed": 4}
    with ResultStore(tmp_path / "results.sqlite") as s:
        msgs = {(r.agent, r.family): (r.message, r.attempts) for r in s.records()}
    assert "waypoints contain NaN" in msgs[("nans", "baseline")][0]
    for fam in ("baseline", "noise"):
        msg, attempts = msgs[("hangs", fam)]
        assert "agent did not answer within 1 s" in msg and attempts == 1


