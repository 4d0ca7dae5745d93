"""Users' agents: check-agent's findings, hung agents under evaluate, and remote agents through a
real `icrsumo serve-agent` process on loopback (identity with in-process, errors, batching)."""

from __future__ import annotations

import json
import os
import re
import sqlite3
import subprocess
import sys
import threading
import time
from contextlib import ExitStack, contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pytest

from icrsumo.agents.base import Action, AgentError, AgentTimeout, EpisodeInfo, Observation
from icrsumo.agents.registry import BUILTIN
from icrsumo.agents.remote import (
    PROTOCOL,
    RemoteAgent,
    decode_action,
    decode_array,
    decode_obs,
    encode_action,
    encode_array,
    encode_obs,
    free_port,
)
from icrsumo.cache import bundled_route
from icrsumo.cli import main
from icrsumo.evaluate import EvalOptions, _Watched, evaluate
from icrsumo.store import ResultStore

AGENTS = Path(__file__).parent / "data" / "agents" / "user_agents.py"
#: non-privileged built-in agents (learned ones, once registered) are served and compared too
SERVABLE = [f"{AGENTS}:BevKeeper"] + sorted(n for n, c in BUILTIN.items()
                                            if not getattr(c, "privileged", True))
INFO = EpisodeInfo("r", "town", "net.xml", 0.05, 0.1, 7)


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    path = tmp_path_factory.getbasetemp() / "icrsumo_cache"  # shared with test_env.py
    old = os.environ.get("ICRSUMO_CACHE")
    os.environ["ICRSUMO_CACHE"] = str(path)
    yield path
    if old is None:
        os.environ.pop("ICRSUMO_CACHE", None)
    else:
        os.environ["ICRSUMO_CACHE"] = old


@pytest.fixture(scope="module")
def suite(cache) -> Path:
    """A convert-routes folder holding tiny_003 (the cached bundled route)."""
    sc_dir, _ = bundled_route("tiny_003")
    return sc_dir.parents[1]


def _obs(t: float = 20.05) -> Observation:
    bev = np.zeros((7, 128, 128), np.uint8)
    bev[0, 40:100, 50:80] = 255
    return Observation(t=t, bev=bev, speed=3.25, instruction="At the T-junction, turn left.",
                       instruction_id=0, notice="")


# --------------------------------------------------------------------------- check-agent
@pytest.mark.parametrize("cls, code, expect", [
    ("Cruise", 0, ["the agent follows the protocol", "deterministic"]),
    ("BevKeeper", 0, ["act_batch() matches act()"]),
    ("NoAct", 1, ["missing method act()"]),
    ("NoName", 1, ["no `name` attribute", "no `privileged` attribute"]),
    ("NaNs", 1, ["act() at decision 1", "waypoints contain NaN"]),
    ("WrongShape", 1, ["waypoints must have shape (N, 2) with N >= 1, got (3,)"]),
    ("ReturnsDict", 1, ["act() returned dict, expected icrsumo.agents.base.Action"]),
    ("Raises", 1, ["act() at decision 3", "raised RuntimeError: agent exploded (at user_agents.py:"]),
    ("NonDeterministic", 1, ["not deterministic: two runs with the same seed differ at decision 1"]),
    ("Hangs", 1, ["act() at decision 3", "did not answer within 1 s"]),
    ("Slow", 1, ["too slow: act() takes 1"]),
])
def test_check_agent_reports_in_plain_words(cache, capsys, cls, code, expect):
    argv = ["check-agent", f"{AGENTS}:{cls}", "--timeout", "1", "--decisions", "30", "--max-act-ms", "50"]
    if cls == "Slow":
        argv[-3:-2] = ["4"]
    assert main(argv) == code
    out = capsys.readouterr().out
    for text in expect:
        assert text in out, out
    assert ("PROBLEM" in out) == (code == 1)


@pytest.mark.parametrize("spec, expect", [
    ("no_such_module_xyz:Agent", "cannot import no_such_module_xyz"),
    ("missing/file.py:Agent", "agent file not found"),
    (f"{AGENTS}:Nope", "has no attribute Nope"),
])
def test_check_agent_bad_input_is_exit_2(cache, capsys, spec, expect):
    assert main(["check-agent", spec]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expect in err[0] and "Traceback" not in err[0]


# --------------------------------------------------------------------------- hung in-process agents
def test_hung_and_dying_agents_are_crashes_and_the_run_completes(suite, tmp_path):
    agents = (f"{AGENTS}:Hangs", f"{AGENTS}:Dies", f"{AGENTS}:Cruise")
    t0 = time.perf_counter()
    summary = evaluate(EvalOptions(out=tmp_path, suite=str(suite), agents=agents, families=("noise",), k=1,
                                   workers=2, quiet=True, agent_timeout=1.0))
    assert time.perf_counter() - t0 < 60
    assert summary["episodes"] == {"done": 2, "crashed": 4}
    with ResultStore(tmp_path / "results.sqlite") as s:
        recs = {(r.agent, r.family): r for r in s.records()}
    for fam in ("baseline", "noise"):
        hung, died = recs[("hangs", fam)], recs[("dies", fam)]
        assert hung.status == "crashed" and hung.attempts == 1  # a hang is not retried
        assert "agent did not answer within 1 s" in hung.message
        assert died.status == "crashed" and died.attempts == 2 and "worker process died" in died.message
        assert recs[("cruise", fam)].status == "done"


def test_alarm_timeout_where_no_parent_watches():
    """Ray workers (no watching parent): SIGALRM interrupts a hung call in the main thread."""
    sys.path.insert(0, str(AGENTS.parent))
    try:
        import user_agents
    finally:
        sys.path.remove(str(AGENTS.parent))
    agent = _Watched(user_agents.Hangs(), None, 0.3)
    agent.reset(INFO)
    agent.act(_obs())
    agent.act(_obs())
    t0 = time.perf_counter()
    with pytest.raises(AgentTimeout, match="agent did not answer within 0.3 s"):
        agent.act(_obs())
    assert time.perf_counter() - t0 < 2


# --------------------------------------------------------------------------- remote agents
def test_codec_round_trips_exactly():
    obs = _obs(t=21.349999999999998)
    back = decode_obs(json.loads(json.dumps(encode_obs(obs))))
    assert np.array_equal(back.bev, obs.bev) and back.bev.dtype == np.uint8
    assert (back.t, back.speed, back.instruction) == (obs.t, obs.speed, obs.instruction)
    assert (back.notice, back.instruction_id) == (obs.notice, obs.instruction_id)
    w = np.array([[2.5, 0.1], [5.0, 1 / 3]])
    a = decode_action(json.loads(json.dumps(encode_action(Action(waypoints=w, target_speed=4.1)))))
    assert np.array_equal(a.waypoints, w) and a.target_speed == 4.1
    arr = np.arange(12, dtype=np.float32).reshape(3, 4)
    assert np.array_equal(decode_array(encode_array(arr), "x"), arr)


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
        urls = [stack.enter_context(served(spec, "--max-batch", "4")) for spec in SERVABLE]
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


def test_server_down_is_one_line_exit_2(tmp_path, capsys):
    port = free_port()
    code = main(["evaluate", "--out", str(tmp_path / "o"), "--quiet", "--agent", f"remote:http://127.0.0.1:{port}"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "not reachable (connection refused)" in err[0]
    assert not (tmp_path / "o").exists()
    assert main(["serve-agent", "route-oracle", "--port", "0"]) == 2
    assert "privileged agent" in capsys.readouterr().err


class _Stub(BaseHTTPRequestHandler):
    """A broken server: /act answers `answer`, slowly when `delay` is set."""

    protocol_version = "HTTP/1.1"
    answer = b"{}"
    delay = 0.0

    def log_message(self, *args):
        pass

    def do_POST(self):  # noqa: N802
        self.rfile.read(int(self.headers["Content-Length"]))
        body = json.dumps({"protocol": PROTOCOL}).encode() if self.path == "/reset" else self.answer
        time.sleep(self.delay if self.path == "/act" else 0.0)
        self.send_response(200)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)


@pytest.mark.parametrize("answer, delay, error, expect", [
    (b"<html>oops</html>", 0.0, AgentError, "answered malformed data: not JSON"),
    (json.dumps({"protocol": "other/9"}).encode(), 0.0, AgentError, "protocol 'other/9'"),
    (json.dumps({"protocol": PROTOCOL, "action": {"waypoints": {"dtype": "uint8", "shape": [2, 2],
                                                                "data": "AAAA"}}}).encode(),
     0.0, AgentError, "action.waypoints: data is not base64 of zlib-compressed bytes"),
    (json.dumps({"protocol": PROTOCOL, "action": {"control": {"steer": "left"}}}).encode(),
     0.0, AgentError, "control.steer must be a number"),
    (json.dumps({"protocol": PROTOCOL}).encode(), 1.5, AgentTimeout, "agent did not answer within 0.3 s"),
])
def test_malformed_or_slow_answers_are_clear_errors(answer, delay, error, expect):
    handler = type("H", (_Stub,), {"answer": answer, "delay": delay})
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    try:
        agent = RemoteAgent(f"http://127.0.0.1:{httpd.server_address[1]}", "stub", timeout=0.3)
        agent.reset(INFO)
        with pytest.raises(error) as err:
            agent.act(_obs())
        assert expect in str(err.value) and "\n" not in str(err.value)
    finally:
        httpd.shutdown()
        httpd.server_close()


class _SlowBatch:
    """A static act_batch(agents, observations) that takes 0.2 s per batch whatever its size, and
    per-episode state (a call counter) kept in each session's own instance."""

    name = "slow-batch"
    privileged = False

    def reset(self, info):
        self.calls = 0

    def act(self, obs):
        return _SlowBatch.act_batch([self], [obs])[0]

    @staticmethod
    def act_batch(agents, observations):
        time.sleep(0.2)
        out = []
        for agent, obs in zip(agents, observations):
            agent.calls += 1
            out.append(Action(waypoints=np.array([[1.0, 0.0]]), target_speed=obs.speed + 100 * agent.calls))
        return out


def test_concurrent_acts_are_batched_with_per_session_state(monkeypatch):
    import icrsumo.agents.registry as registry
    from icrsumo.agents.serve import AgentServer

    monkeypatch.setitem(registry.BUILTIN, "slow-batch", _SlowBatch)
    server = AgentServer("slow-batch", max_batch=4).start()
    try:
        agents = [RemoteAgent(server.url, "slow-batch", timeout=10) for _ in range(6)]
        for a in agents:
            a.reset(INFO)
        results: list[list[float]] = [[] for _ in agents]

        def drive(i):
            for _ in range(2):
                obs = Observation(0.0, np.zeros((7, 4, 4), np.uint8), float(i), "", -1, "")
                results[i].append(agents[i].act(obs).target_speed)

        t0 = time.perf_counter()
        threads = [threading.Thread(target=drive, args=(i,)) for i in range(6)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        elapsed = time.perf_counter() - t0
        assert results == [[100.0 + i, 200.0 + i] for i in range(6)]  # each session its own answers
        stats = server.stats
        assert stats["acts"] == 12 and 1 < stats["largest_batch"] <= 4 and stats["batches"] < 12
        assert elapsed < 12 * 0.2
        for a in agents:
            a.close()
        assert len(server.sessions) == 0
    finally:
        server.shutdown()
