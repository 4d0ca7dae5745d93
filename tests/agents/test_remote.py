"""Remote agents without SUMO: the icrsumo-agent/1 codec, clear errors for broken or slow
servers and for a server that is down, and the reference server batching concurrent acts."""

from __future__ import annotations

import json
import threading
import time
from contextlib import contextmanager
from dataclasses import replace
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
import pytest

from icrsumo.agents.base import Action, AgentError, AgentTimeout, EpisodeInfo, Observation
from icrsumo.agents.registry import register, unregister
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
from icrsumo.app.cli.main import main
from icrsumo.world.dynamics import Control

INFO = EpisodeInfo("r", "town", "net.xml", 0.05, 0.1, 7)


def _obs(t: float = 20.05) -> Observation:
    bev = np.zeros((7, 128, 128), np.uint8)
    bev[0, 40:100, 50:80] = 255
    return Observation(t=t, bev=bev, speed=3.25, instruction="At the T-junction, turn left.",
                       instruction_id=0, notice="", compass=-2.75)


def test_codec_round_trips_exactly():
    obs = _obs(t=21.349999999999998)
    back = decode_obs(json.loads(json.dumps(encode_obs(obs))))
    assert np.array_equal(back.bev, obs.bev) and back.bev.dtype == np.uint8
    assert (back.t, back.speed, back.instruction) == (obs.t, obs.speed, obs.instruction)
    assert back.compass == obs.compass
    # an older client sends no compass: it reads 0
    old = {k: v for k, v in encode_obs(obs).items() if k != "compass"}
    assert decode_obs(old).compass == 0.0
    assert (back.notice, back.instruction_id) == (obs.notice, obs.instruction_id)
    w = np.array([[2.5, 0.1], [5.0, 1 / 3]])
    a = decode_action(json.loads(json.dumps(encode_action(Action(waypoints=w, target_speed=4.1)))))
    assert np.array_equal(a.waypoints, w) and a.target_speed == 4.1
    arr = np.arange(12, dtype=np.float32).reshape(3, 4)
    assert np.array_equal(decode_array(encode_array(arr), "x"), arr)


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


def test_concurrent_acts_are_batched_with_per_session_state():
    from icrsumo.agents.hosting.serve import AgentServer

    register("slow-batch", _SlowBatch)
    try:
        server = AgentServer("slow-batch", max_batch=4).start()
    finally:
        unregister("slow-batch")
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


class _Cruise:
    name, privileged = "cruise-key", False

    def reset(self, info):
        pass

    def act(self, obs):
        return Action(waypoints=np.array([[2.5, 0.0]]), target_speed=3.0)


def _post(url: str, path: str, body: bytes, headers: dict | None = None) -> tuple[int, dict]:
    import http.client
    from urllib.parse import urlsplit

    u = urlsplit(url)
    conn = http.client.HTTPConnection(u.hostname, u.port, timeout=10)
    conn.request("POST", path, body=body, headers={"Content-Type": "application/json", **(headers or {})})
    resp = conn.getresponse()
    status, doc = resp.status, json.loads(resp.read())
    conn.close()
    return status, doc


def test_a_shared_key_guards_the_server_and_hostile_json_is_a_400(monkeypatch, capsys):
    from icrsumo.agents.hosting.serve import AgentServer
    from icrsumo.agents.remote import RemoteFactory
    from icrsumo.core.errors import InputError

    register("cruise-key", _Cruise)
    try:
        server = AgentServer("cruise-key", key="s3cret").start()
    finally:
        unregister("cruise-key")
    try:
        with pytest.raises(InputError, match="requires its shared key"):
            RemoteFactory(server.url)
        with pytest.raises(InputError, match="the shared key variable ICR_TEST_KEY is not set"):
            RemoteFactory(server.url + "?key_env=ICR_TEST_KEY")
        monkeypatch.setenv("ICR_TEST_KEY", "wrong")
        with pytest.raises(InputError, match="requires its shared key"):
            RemoteFactory(server.url + "?key_env=ICR_TEST_KEY")
        monkeypatch.setenv("ICR_TEST_KEY", "s3cret")
        agent = RemoteFactory(server.url + "?key_env=ICR_TEST_KEY")()
        agent.reset(INFO)
        assert agent.act(_obs()).target_speed == 3.0
        agent.close()
        auth = {"Authorization": "Bearer s3cret"}
        nested = b"[" * 100000 + b"]" * 100000
        deep = b'{"protocol": "' + PROTOCOL.encode() + b'", "session": "a", "info": ' + nested + b"}"
        status, doc = _post(server.url, "/reset", deep, auth)
        assert status == 400 and "nested too deeply" in doc["error"]
        inf = json.dumps({"protocol": PROTOCOL, "session": "a", "info": {**json.loads(json.dumps(
            {"route_id": "r", "town": "t", "net": "n", "step_length": 0.05, "control_dt": 0.1}))}}).encode()
        inf = inf[:-2] + b', "seed": Infinity}}'
        status, doc = _post(server.url, "/reset", inf, auth)
        assert status == 400 and "Infinity is not a JSON number" in doc["error"]
    finally:
        server.shutdown()


def test_serving_beyond_the_loopback_without_a_key_says_so(monkeypatch, capsys):
    import icrsumo.agents.hosting.serve as serve_mod

    monkeypatch.setattr(serve_mod.AgentServer, "serve_forever", lambda self: None)   # start, say, stop
    monkeypatch.setattr(serve_mod.AgentServer, "shutdown", lambda self: self.httpd.server_close())
    register("cruise-key", _Cruise)
    try:
        serve_mod.serve("cruise-key", host="0.0.0.0", port=0)
        assert "has no authentication" in capsys.readouterr().err
        monkeypatch.setenv("ICR_TEST_KEY", "k")
        serve_mod.serve("cruise-key", host="0.0.0.0", port=0, key_env="ICR_TEST_KEY")
        assert "no authentication" not in capsys.readouterr().err
    finally:
        unregister("cruise-key")


class _Echo(BaseHTTPRequestHandler):
    """A server that keeps the Authorization header of every request (``said``), answers
    ``/info``, ``/reset`` and ``/close`` and refuses ``/act`` quoting that header; ``moved``: a
    URL it redirects every request to instead; ``trickle``: s between the bytes of an answer."""

    protocol_version = "HTTP/1.1"
    said: list[str] = []
    moved = ""
    trickle = 0.0

    def log_message(self, *args):
        pass

    def _answer(self, status: int, doc: dict) -> None:
        type(self).said.append(self.headers.get("Authorization", ""))
        body = json.dumps({"protocol": PROTOCOL, **doc}).encode()
        self.send_response(302 if self.moved else status)
        self.send_header("Content-Length", str(len(body)))
        if self.moved:
            self.send_header("Location", self.moved + self.path)
        self.end_headers()
        try:
            for i in range(len(body)):
                self.wfile.write(body[i:i + 1])
                self.wfile.flush()
                time.sleep(self.trickle)
        except (BrokenPipeError, ConnectionResetError):
            pass

    def do_GET(self):  # noqa: N802
        self._answer(200, {"name": "echo"})

    def do_POST(self):  # noqa: N802
        self.rfile.read(int(self.headers["Content-Length"]))
        if self.path == "/act":
            self._answer(401, {"error": f"bad credentials {self.headers.get('Authorization')}"})
        else:
            self._answer(200, {})


@contextmanager
def _echo(**attrs):
    handler = type("E", (_Echo,), {"said": [], **attrs})
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    try:
        yield httpd.server_address[1], handler
    finally:
        httpd.shutdown()
        httpd.server_close()


def test_a_password_in_the_url_goes_as_basic_auth_and_is_redacted_everywhere():
    import base64

    from icrsumo.agents.remote import RemoteFactory

    with _echo() as (port, handler):
        url = f"http://alice:pa%40ss-word-42@127.0.0.1:{port}"
        factory = RemoteFactory(url)
        token = base64.b64encode(b"alice:pa@ss-word-42").decode()
        assert handler.said == [f"Basic {token}"]
        assert factory.fingerprint == f"remote echo at http://alice:***@127.0.0.1:{port}"
        agent = factory()
        agent.reset(INFO)
        with pytest.raises(AgentError) as err:
            agent.act(_obs())
        agent.close()
    line = str(err.value)
    assert line == f"remote agent at http://alice:***@127.0.0.1:{port}: bad credentials Basic ***"
    assert all(secret not in line for secret in ("pa%40ss", "pa@ss", token))


def test_a_redirect_is_not_followed_so_the_key_stays_with_its_server(monkeypatch):
    from icrsumo.agents.remote import RemoteFactory
    from icrsumo.core.errors import InputError

    monkeypatch.setenv("ICR_TEST_KEY", "s3cret-key-77")
    with _echo() as (other, elsewhere), _echo(moved=f"http://127.0.0.1:{other}") as (port, handler):
        with pytest.raises(InputError, match="answered HTTP 302, a redirect, which is not followed"):
            RemoteFactory(f"http://127.0.0.1:{port}?key_env=ICR_TEST_KEY")
        assert handler.said == ["Bearer s3cret-key-77"] and elsewhere.said == []


def test_the_timeout_is_a_deadline_for_the_whole_request():
    """An answer trickled a byte every 0.05 s (about 2 s in all) is cut off after 0.3 s."""
    with _echo(trickle=0.05) as (port, _):
        agent = RemoteAgent(f"http://127.0.0.1:{port}", "echo", timeout=0.3)
        with pytest.raises(AgentTimeout, match="agent did not answer within 0.3 s"):
            agent.reset(INFO)
        agent.close()


# --------------------------------------------------------------------------- asking for clarification
def test_asking_travels_both_ways_and_messages_without_it_are_unchanged():
    from icrsumo.agents.remote import ProtocolError, decode_info, encode_info

    # absent when false: the messages of a run without asking are those of before
    assert "asking" not in encode_info(INFO) and "answer" not in encode_obs(_obs())
    assert "ask" not in encode_action(Action(waypoints=np.array([[2.5, 0.0]])))
    assert decode_info(json.loads(json.dumps(encode_info(INFO)))) == INFO
    asking = replace(INFO, asking=True)
    assert encode_info(asking)["asking"] is True and decode_info(encode_info(asking)) == asking
    answer = replace(_obs(), answer=True)
    assert decode_obs(json.loads(json.dumps(encode_obs(answer)))).answer is True
    for action in (Action(waypoints=np.array([[2.5, 0.0]]), target_speed=3.0, ask=True),
                   Action(control=Control(0.0, 0.5, 0.0), ask=True)):
        back = decode_action(json.loads(json.dumps(encode_action(action))))
        assert back.ask is True and decode_action(encode_action(replace(action, ask=False))).ask is False
    with pytest.raises(ProtocolError, match="action.ask must be true or false, got int"):
        decode_action({**encode_action(Action(waypoints=np.array([[2.5, 0.0]]))), "ask": 1})
    with pytest.raises(ProtocolError, match="obs.answer must be true or false, got str"):
        decode_obs({**encode_obs(_obs()), "answer": "yes"})
    with pytest.raises(ProtocolError, match="info.asking must be true or false"):
        decode_info({**encode_info(INFO), "asking": None})


class _AskUntilAnswered:
    """Drives straight on slowly and, when the run lets it ask, asks at every step until the
    navigator's answer arrives (so the log shows whether info.asking, action.ask and obs.answer
    all travelled)."""

    name, privileged = "ask-until-answered", False

    def reset(self, info):
        self.asking, self.answered = info.asking, False

    def act(self, obs):
        self.answered = self.answered or obs.answer
        return Action(waypoints=np.array([[2.5, 0.0], [5.0, 0.0]]), target_speed=3.0,
                      ask=self.asking and not self.answered)


@pytest.mark.sumo
def test_a_remote_agent_asks_and_reads_the_answer_over_http_as_in_process(cache):
    """The agent behind a real serve-agent server on 127.0.0.1: the same asks and the same log as
    in-process (info.asking went to it, its asks came back, the answer reached it)."""
    from icrsumo.agents.hosting.serve import AgentServer
    from icrsumo.evaluation.bundled import bundled_route
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.results.logs import dumps_log
    from icrsumo.sim.episode import RunOptions, run_episode
    from icrsumo.world.scenario import read_scenario

    sc_dir, instr = bundled_route("tiny_003")
    sc = read_scenario(sc_dir)
    sets = {(s.family, s.k): s for s in read_instruction_sets(instr)}
    local = run_episode(sc, sets[("ambiguity", 0)], _AskUntilAnswered(), RunOptions(asking=True),
                        baseline=sets[("baseline", 0)])
    assert len(local.asks) > 5 and sum(a.answered for a in local.asks) == 1
    register("ask-until-answered", _AskUntilAnswered)
    try:
        server = AgentServer("ask-until-answered").start()
    finally:
        unregister("ask-until-answered")
    logs = []
    try:
        for options in (RunOptions(asking=True), RunOptions()):
            agent = RemoteAgent(server.url, "ask-until-answered", timeout=30)
            logs.append(run_episode(sc, sets[("ambiguity", 0)], agent, options,
                                    baseline=sets[("baseline", 0)]))
            agent.close()
    finally:
        server.shutdown()
    remote, off = logs
    assert dumps_log(remote) == dumps_log(local)
    # without asking it never asks, and drives as it did
    assert off.asks == () and dumps_log(off) == dumps_log(replace(local, asks=()))
