"""The LLM interpreter without SUMO: its spec, request, answer parsing, response cache and the
client's answers to a server that misbehaves (a small HTTP server on 127.0.0.1 that sends what
each test tells it to: malformed, empty, huge or late answers, errors, nothing at all)."""

from __future__ import annotations

import json
import os
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest

from icrsumo.agents import registry
from icrsumo.agents.base import AgentError
from icrsumo.agents.llm import (
    LLM_PREFIX,
    MENU,
    SCHEMA,
    Asker,
    LLMFactory,
    LLMSettings,
    Scene,
    api_key,
    build_request,
    check_server,
    parse_answer,
    parse_spec,
    with_options,
)
from icrsumo.agents.registry import agent_factory
from icrsumo.agents.remote import free_port
from icrsumo.core.errors import InputError
from icrsumo.core.llmio import Invalid, ResponseCache, request_hash
from icrsumo.core.types import Intent

SCENE = Scene(speed=8.26, lane=1, lanes=2, junction_m=35.4, branches=("left", "straight"), light="green",
              lead_m=None)


# --------------------------------------------------------------------------- spec
def test_a_spec_names_model_server_and_options():
    s = parse_spec("llm:Qwen/Qwen2.5-7B-Instruct@http://127.0.0.1:8000/v1?key_env=MY_KEY&image=1&timeout=5")
    assert (s.model, s.endpoint, s.key_env, s.image, s.timeout) == (
        "Qwen/Qwen2.5-7B-Instruct", "http://127.0.0.1:8000/v1", "MY_KEY", True, 5.0)
    assert s.name == "llm:Qwen/Qwen2.5-7B-Instruct+image"
    assert parse_spec("llm:smollm2@https://example.org/v1").name == "llm:smollm2"
    assert isinstance(agent_factory("llm:smollm2@http://127.0.0.1:1/v1"), LLMFactory)  # no network yet
    assert LLM_PREFIX == registry.LLM_PREFIX


@pytest.mark.parametrize("spec, words", [
    ("llm:smollm2", "needs a model and a server URL"),
    ("llm:@http://127.0.0.1:1/v1", "needs a model"),
    ("llm:smollm2@ftp://x/v1", "needs a model and a server URL"),
    ("llm:smollm2@http://127.0.0.1:1/v1?colour=red", "unknown option 'colour'"),
    ("llm:smollm2@http://127.0.0.1:1/v1?key_env=sk-123", "is not a variable name"),
    ("llm:smollm2@http://127.0.0.1:1/v1?format=yaml", "format='yaml'"),
    ("llm:smollm2@http://127.0.0.1:1/v1?timeout=nan", "timeout='nan'"),
    ("llm:smollm2@http://127.0.0.1:1/v1?seed=-1", "seed='-1'"),
])
def test_bad_specs_are_one_line_input_errors(spec, words):
    with pytest.raises(InputError) as err:
        parse_spec(spec)
    assert words in str(err.value) and "\n" not in str(err.value)


def test_the_command_line_options_go_into_the_spec():
    spec = with_options("llm:m@http://127.0.0.1:1/v1", "OPENAI_API_KEY", True)
    assert spec == "llm:m@http://127.0.0.1:1/v1?key_env=OPENAI_API_KEY&image=1"
    assert parse_spec(with_options(spec + "", None, False)).image
    assert with_options("bev-ngram", "X", True) == "bev-ngram"


def test_the_fingerprint_covers_what_changes_a_request_not_the_address():
    a = LLMFactory(parse_spec("llm:m@http://127.0.0.1:1/v1"))
    assert a.fingerprint == LLMFactory(parse_spec("llm:m@http://10.0.0.9:8000/v1?key_env=K")).fingerprint
    assert a.fingerprint != LLMFactory(parse_spec("llm:other@http://127.0.0.1:1/v1")).fingerprint
    assert a.fingerprint != LLMFactory(parse_spec("llm:m@http://127.0.0.1:1/v1?image=1")).fingerprint
    assert a.fingerprint != LLMFactory(parse_spec("llm:m@http://127.0.0.1:1/v1?seed=3")).fingerprint


# --------------------------------------------------------------------------- request and answer
def test_the_request_holds_the_instruction_as_received_and_the_scene():
    s = LLMSettings("m", "http://127.0.0.1:1/v1")
    body = build_request(s, 'Turn "left" here', SCENE)
    user = body["messages"][1]["content"]
    assert 'Instruction: "Turn \\"left\\" here"' in user
    assert "speed 8 m/s; lane 1 of 2 (counted from the right); next junction in 35 m, branches: left, " \
           "straight; traffic light: green; vehicle ahead: none" in user
    assert body["temperature"] == 0 and body["seed"] == 0 and body["max_tokens"] > 0
    assert body["response_format"] == {"type": "json_object", "schema": SCHEMA}
    assert SCHEMA["properties"]["maneuver"]["enum"] == [m.value for m in MENU]
    strict = build_request(LLMSettings("m", "u", format="json_schema"), "x", SCENE)
    assert strict["response_format"]["json_schema"]["schema"] == SCHEMA
    assert "response_format" not in build_request(LLMSettings("m", "u", format="none"), "x", SCENE)
    image = build_request(LLMSettings("m", "u", image=True), "x", SCENE, png=b"\x89PNG")
    parts = image["messages"][1]["content"]
    assert parts[0]["type"] == "text" and parts[1]["image_url"]["url"].startswith("data:image/png;base64,")
    assert request_hash(body) == request_hash(json.loads(json.dumps(body)))  # key order does not matter


@pytest.mark.parametrize("content, maneuver", [
    ('{"maneuver": "left"}', Intent.LEFT),
    (' {"maneuver": " Lane_Right "} ', Intent.LANE_RIGHT),
    ('Sure:\n```json\n{"maneuver": "stop"}\n```', Intent.STOP),
])
def test_valid_answers(content, maneuver):
    assert parse_answer(content) == maneuver


@pytest.mark.parametrize("content, problem", [
    ("left", "not JSON"),
    ('{"action": "left"}', 'key "maneuver"'),
    ('{"maneuver": "u-turn"}', "not on the menu"),
    ('{"maneuver": 3}', "not on the menu"),
    ('["left"]', 'key "maneuver"'),
    ("[" * 100_000, "not JSON"),
])
def test_anything_else_is_an_invalid_answer(content, problem):
    with pytest.raises(Invalid) as err:
        parse_answer(content)
    assert problem in str(err.value)


# --------------------------------------------------------------------------- a misbehaving server
class _Server:
    """An HTTP server on 127.0.0.1 whose answers a test sets: ``replies`` is a list of
    (status, body bytes, delay s) used in turn (the last one repeats), sent as ``content_type``;
    ``models``: the ids ``GET /models`` lists (None: 404), unless ``models_reply`` (status,
    body, content type) overrides it; ``echo``: a status with which every request is answered
    ``{"error": {"message": "invalid key <its Authorization header>"}}``; ``moved``: request path
    -> the URL a 302 sends it to; ``trickle``: s between the bytes of an answer.
    ``headers``: the headers of every request it got."""

    def __init__(self) -> None:
        self.replies: list[tuple[int, bytes, float]] = [(200, b"{}", 0.0)]
        self.content_type = "application/json"
        self.models: list[str] | None = ["smollm2"]
        self.models_reply: tuple[int, bytes, str] | None = None
        self.echo: int | None = None
        self.moved: dict[str, str] = {}
        self.trickle = 0.0
        self.hits = 0
        self.headers: list[dict[str, str]] = []
        owner = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):  # quiet
                pass

            def _send(self, status: int, body: bytes, kind: str = "") -> None:
                self.send_response(status)
                self.send_header("Content-Type", kind or owner.content_type)
                self.send_header("Content-Length", str(len(body)))
                if self.path in owner.moved:
                    self.send_header("Location", owner.moved[self.path])
                self.end_headers()
                try:
                    for i in range(len(body)) if owner.trickle else ():
                        self.wfile.write(body[i:i + 1])
                        self.wfile.flush()
                        time.sleep(owner.trickle)
                    self.wfile.write(b"" if owner.trickle else body)
                except (BrokenPipeError, ConnectionResetError):
                    pass

            def _special(self) -> bool:
                owner.headers.append(dict(self.headers))
                if self.path in owner.moved:
                    self._send(302, b"")
                elif owner.echo is not None:
                    said = self.headers.get("Authorization", "")
                    self._send(owner.echo, json.dumps({"error": {"message": f"invalid key {said}"}}).encode())
                return self.path in owner.moved or owner.echo is not None

            def do_GET(self):
                if self._special():
                    return
                if owner.models_reply is not None:
                    self._send(*owner.models_reply)
                elif owner.models is None:
                    self._send(404, b'{"error": "no such path"}')
                else:
                    self._send(200, json.dumps({"data": [{"id": m} for m in owner.models]}).encode())

            def do_POST(self):
                self.rfile.read(int(self.headers.get("Content-Length", 0)))
                if self._special():
                    return
                status, body, delay = owner.replies[min(owner.hits, len(owner.replies) - 1)]
                owner.hits += 1
                time.sleep(delay)
                self._send(status, body)

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.port = self.httpd.server_address[1]
        self.endpoint = f"http://127.0.0.1:{self.port}/v1"
        threading.Thread(target=self.httpd.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()


@pytest.fixture()
def server():
    s = _Server()
    yield s
    s.close()


def _chat(content) -> bytes:
    return json.dumps({"choices": [{"message": {"role": "assistant", "content": content},
                                    "finish_reason": "stop"}]}).encode()


def _ask(server, tmp_path: Path | None = None, endpoint: str | None = None, **kw):
    settings = LLMSettings("smollm2", endpoint or server.endpoint, cache_dir=tmp_path, **kw)
    return Asker(settings, kw.get("key_env") and api_key(settings)).ask(
        build_request(settings, "Turn left at the junction.", SCENE))


@pytest.mark.parametrize("reply, problem", [
    (_chat(""), "answer is empty"),
    (_chat(None), "answer is empty"),
    (_chat("I would turn left."), "answer is not JSON"),
    (_chat('{"maneuver": "fly"}'), "not on the menu"),
])
def test_empty_or_prose_answers_are_invalid_never_a_crash(server, reply, problem):
    server.replies = [(200, reply, 0.0)]
    key, answer = _ask(server)
    assert not answer.valid and answer.maneuver == Intent.FOLLOW and problem in answer.problem


PAGE = b"<!doctype html><html><body>Welcome to the admin console</body></html>"


@pytest.mark.parametrize("reply, kind, words", [
    (PAGE, "text/html", "answered HTTP 200 with text/html ('<!doctype html><html><body>Welcome to the "
                        "admin console</body></html>'), not an OpenAI-compatible JSON answer (the body is "
                        "not JSON)"),
    (b'{"choices": []}', "application/json", "not an OpenAI-compatible JSON answer (no choices[0])"),
    (b'{"choices": [{"message": {"content": ["left"]}}]}', "application/json",
     "not an OpenAI-compatible JSON answer (no choices[0].message.content text)"),
    (_chat("x" * 100_000), "application/json", "response larger than 65536 bytes"),
])
def test_a_body_that_is_not_an_openai_answer_is_a_server_fault_never_cached(server, tmp_path, reply, kind,
                                                                          words):
    server.replies, server.content_type = [(200, reply, 0.0)], kind
    with pytest.raises(AgentError) as err:
        _ask(server, tmp_path)
    line = str(err.value)
    assert line.startswith(f"LLM server {server.endpoint}/chat/completions for model smollm2: ")
    assert words in line
    assert len(ResponseCache(tmp_path)) == 0 and server.hits == 2   # retried once, nothing stored
    # the right server later: its answer is the one the run keeps
    server.replies, server.content_type = [(200, _chat('{"maneuver": "left"}'), 0.0)], "application/json"
    assert _ask(server, tmp_path)[1].maneuver == Intent.LEFT and len(ResponseCache(tmp_path)) == 1


def test_a_page_an_earlier_version_cached_as_an_answer_is_asked_again(server, tmp_path):
    settings = LLMSettings("smollm2", server.endpoint, cache_dir=tmp_path)
    body = build_request(settings, "Turn left at the junction.", SCENE)
    ResponseCache(tmp_path).put(request_hash(body), body, content=None, problem="response body is not JSON")
    server.replies = [(200, _chat('{"maneuver": "left"}'), 0.0)]
    assert _ask(server, tmp_path)[1].maneuver == Intent.LEFT and server.hits == 1


def test_the_server_check_refuses_a_page_that_is_not_an_openai_server(server):
    server.models_reply = (200, PAGE, "text/html")
    with pytest.raises(InputError) as err:
        check_server(LLMSettings("smollm2", server.endpoint), has_cache=True)
    assert f"the LLM server {server.endpoint}/models answered HTTP 200 with text/html ('<!doctype html>" \
        in str(err.value) and "not an OpenAI-compatible JSON answer" in str(err.value)
    assert "\n" not in str(err.value)


def test_answers_are_cached_by_request_and_replayed_without_the_server(server, tmp_path):
    server.replies = [(200, _chat('{"maneuver": "right"}'), 0.0)]
    key, first = _ask(server, tmp_path)
    assert first.maneuver == Intent.RIGHT and server.hits == 1
    rec = json.loads(ResponseCache(tmp_path).path(key).read_text())
    assert rec["request"]["model"] == "smollm2" and rec["content"] == '{"maneuver": "right"}'
    server.close()
    again = Asker(LLMSettings("smollm2", server.endpoint, cache_dir=tmp_path))
    _, answer = again.ask(build_request(again.settings, "Turn left at the junction.", SCENE))
    assert answer == first and again.hits == 1 and again.sent == 0


def test_an_invalid_answer_is_cached_too(server, tmp_path):
    server.replies = [(200, _chat("no idea"), 0.0)]
    _ask(server, tmp_path)
    server.replies = [(200, _chat('{"maneuver": "left"}'), 0.0)]
    _, answer = _ask(server, tmp_path)
    assert not answer.valid and server.hits == 1   # the rerun is the same run


@pytest.mark.parametrize("replies, words", [
    ([(500, b'{"error": {"message": "model crashed"}}', 0.0)], "HTTP 500: model crashed"),
    ([(404, b'{"error": "model not found"}', 0.0)], "HTTP 404: model not found"),
    ([(200, _chat('{"maneuver": "left"}'), 1.5)], "timed out after 0.5 s"),
])
def test_server_errors_and_timeouts_crash_the_episode_with_the_reason(server, replies, words):
    server.replies = replies
    with pytest.raises(AgentError) as err:
        _ask(server, timeout=0.5)
    assert words in str(err.value) and "smollm2" in str(err.value)
    assert server.hits == (1 if "404" in words else 2)   # a client error is not retried


def test_a_server_error_then_an_answer_is_retried(server):
    server.replies = [(503, b"busy", 0.0), (200, _chat('{"maneuver": "straight"}'), 0.0)]
    assert _ask(server)[1].maneuver == Intent.STRAIGHT


def test_the_timeout_is_a_deadline_for_the_whole_request(server):
    """A server that trickles a valid answer (a byte every 0.05 s, about 3 s in all) is cut off
    at the deadline, by the planning-time check and by a question alike."""
    server.trickle = 0.05
    server.replies = [(200, _chat('{"maneuver": "left"}'), 0.0)]
    with pytest.raises(AgentError, match="timed out after 0.3 s"):
        _ask(server, timeout=0.3)
    with pytest.raises(InputError, match="does not answer \\(timed out after 0.3 s\\)"):
        check_server(LLMSettings("smollm2", server.endpoint, timeout=0.3), has_cache=False)


def test_the_server_check_names_served_models_and_missing_keys(server, monkeypatch):
    with pytest.raises(InputError) as err:
        check_server(LLMSettings("gpt-9", server.endpoint), has_cache=False)
    assert "does not serve model 'gpt-9' (it serves: smollm2)" in str(err.value)
    server.models = None   # a server without GET /models is taken at its word
    assert check_server(LLMSettings("gpt-9", server.endpoint), has_cache=False) is False
    monkeypatch.delenv("ICRSUMO_TEST_KEY", raising=False)
    with pytest.raises(InputError, match="the API key variable ICRSUMO_TEST_KEY is not set"):
        check_server(LLMSettings("smollm2", server.endpoint, key_env="ICRSUMO_TEST_KEY"), has_cache=False)
    dead = f"http://127.0.0.1:{free_port()}/v1"
    with pytest.raises(InputError, match="does not answer \\(connection refused\\)"):
        check_server(LLMSettings("smollm2", dead), has_cache=False)
    assert check_server(LLMSettings("smollm2", dead), has_cache=True) is True   # answered from the cache


# --------------------------------------------------------------------------- credentials
KEY = "sk-test-0123456789abcdef"


@pytest.fixture()
def other():
    """A second server, on another port of 127.0.0.1: another origin."""
    s = _Server()
    yield s
    s.close()


def test_the_key_is_never_sent_to_another_origin(server, other, monkeypatch):
    monkeypatch.setenv("ICRSUMO_TEST_KEY", KEY)
    elsewhere = f"http://127.0.0.1:{other.port}"
    server.moved = {"/v1/models": f"{elsewhere}/v1/models", "/v1/chat/completions": f"{elsewhere}/v1/chat"}
    settings = LLMSettings("smollm2", server.endpoint, key_env="ICRSUMO_TEST_KEY")
    with pytest.raises(InputError) as err:
        check_server(settings, has_cache=False)
    assert f"redirected (HTTP 302) to another origin, {elsewhere}/v1/models" in str(err.value)
    other.replies = [(200, _chat('{"maneuver": "left"}'), 0.0)]
    with pytest.raises(AgentError, match="redirected \\(HTTP 302\\) to another origin"):
        _ask(server, key_env="ICRSUMO_TEST_KEY")
    assert other.headers == [] and server.headers[0]["Authorization"] == f"Bearer {KEY}"
    server.moved = {"/v1/models": f"http://localhost:{server.port}/v1/models"}   # another host name
    with pytest.raises(InputError, match="to another origin"):
        check_server(settings, has_cache=False)


def test_a_redirect_within_the_origin_is_followed(server, monkeypatch):
    monkeypatch.setenv("ICRSUMO_TEST_KEY", KEY)
    server.moved = {"/v1/models": "/api/models"}
    assert check_server(LLMSettings("smollm2", server.endpoint, key_env="ICRSUMO_TEST_KEY"), False) is False
    assert [h["Authorization"] for h in server.headers] == [f"Bearer {KEY}"] * 2


@pytest.mark.parametrize("status", [401, 500])
def test_a_server_quoting_the_key_has_it_redacted(server, tmp_path, monkeypatch, status):
    monkeypatch.setenv("ICRSUMO_TEST_KEY", KEY)
    server.echo = status
    settings = LLMSettings("smollm2", server.endpoint, key_env="ICRSUMO_TEST_KEY", cache_dir=tmp_path)
    with pytest.raises((InputError, AgentError)) as err:
        if status == 401:
            check_server(settings, has_cache=False)
        _ask(server, tmp_path, key_env="ICRSUMO_TEST_KEY")
    assert f"HTTP {status}: invalid key Bearer ***" in str(err.value) and KEY not in str(err.value)
    assert server.headers[-1]["Authorization"] == f"Bearer {KEY}"   # the key itself went to its server


def test_a_password_in_the_url_goes_as_basic_auth_and_is_never_shown(server, tmp_path):
    import base64

    url = f"http://alice:pa%40ss-word-42@127.0.0.1:{server.port}/v1"
    spec = parse_spec(f"llm:smollm2@{url}")
    assert check_server(spec, has_cache=False) is False
    token = base64.b64encode(b"alice:pa@ss-word-42").decode()
    assert server.headers[-1]["Authorization"] == f"Basic {token}"
    server.echo = 500
    with pytest.raises(AgentError) as err:
        _ask(server, tmp_path, endpoint=url)
    assert f"LLM server http://alice:***@127.0.0.1:{server.port}/v1/chat/completions" in str(err.value)
    assert "HTTP 500: invalid key Basic ***" in str(err.value)
    assert "pa%40ss" not in str(err.value) and "pa@ss" not in str(err.value) and token not in str(err.value)
    with pytest.raises(InputError) as bad:
        parse_spec(f"llm:smollm2@{url}?colour=red")
    assert "alice:***@127.0.0.1" in str(bad.value) and "pa%40ss" not in str(bad.value)


# --------------------------------------------------------------------------- the cache folder
def test_an_unwritable_cache_is_an_error_before_any_episode(server, tmp_path):
    factory = LLMFactory(LLMSettings("smollm2", server.endpoint))
    (tmp_path / "llm-cache").write_text("not a folder")
    with pytest.raises(InputError) as err:
        factory.bind(tmp_path)
    line = str(err.value)
    assert line.startswith(f"{tmp_path / 'llm-cache'}: the LLM response cache cannot be written: ")
    assert "is a file, not a folder" in line and "(fix: make it writable" in line
    (tmp_path / "out").write_text("a file where the out folder would be")
    with pytest.raises(InputError, match="is a file, not a folder"):
        factory.bind(tmp_path / "out")
    assert factory.bind(tmp_path / "fresh").settings.cache_dir == tmp_path / "fresh" / "llm-cache"
    assert not (tmp_path / "fresh").exists()   # checked, not created


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes whatever the permissions say")
def test_a_cache_without_write_permission_is_an_error(server, tmp_path):
    cache = tmp_path / "llm-cache"
    (cache / "ab").mkdir(parents=True)
    (cache / "ab").chmod(0o500)
    try:
        with pytest.raises(InputError, match=f"no permission to write in {cache / 'ab'}"):
            LLMFactory(LLMSettings("smollm2", server.endpoint)).bind(tmp_path)
    finally:
        (cache / "ab").chmod(0o700)


def test_with_images_the_bev_raster_goes_along_as_png():
    import numpy as np

    from icrsumo.agents.base import Observation
    from icrsumo.agents.llm import LLMFollower
    from icrsumo.render import CHANNELS

    agent = LLMFollower(parse_spec("llm:vlm@http://127.0.0.1:1/v1?image=1"))
    bev = np.zeros((len(CHANNELS), 16, 16), np.uint8)
    bev[0, 4:12, 4:12] = 1
    png = agent._png(Observation(t=0.0, bev=bev, speed=0.0, instruction="", instruction_id=-1, notice=""))
    assert png.startswith(b"\x89PNG\r\n\x1a\n") and png == agent._png(
        Observation(t=1.0, bev=bev.copy(), speed=1.0, instruction="x", instruction_id=0, notice=""))
    assert agent.name == "llm:vlm+image"


# --------------------------------------------------------------------------- real evaluations
def _evaluate(suite: Path, out: Path, agent: str, *extra: str, env: dict | None = None):
    """``python -m icrsumo evaluate`` of tiny_003 (baseline and noise, K = 1) in a subprocess."""
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "icrsumo", "evaluate", "--suite", str(suite), "--family", "noise",
           "--k", "1", "--workers", "1", "--out", str(out), "--agent", agent, *extra]
    return subprocess.run(cmd, capture_output=True, timeout=600, env={**os.environ, **(env or {})})


def _leaks(out: Path, proc, secrets: list[str]) -> list[str]:
    """The files under ``out`` (and stdout / stderr) that hold one of ``secrets``."""
    places = {str(p): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    places.update(stdout=proc.stdout, stderr=proc.stderr)
    return [f"{where}: {s}" for where, data in places.items() for s in secrets if s.encode() in data]


def _messages(out: Path) -> list[str]:
    from icrsumo.results.store import ResultStore

    with ResultStore(out / "results.sqlite") as store:
        return [r.message for r in store.records()]


@pytest.mark.sumo
@pytest.mark.parametrize("case", ["key", "password"])
def test_credentials_a_server_quotes_reach_no_output(suite, server, tmp_path, case):
    """A server that quotes the Authorization header in its errors: the episodes crash with the
    error stored, and neither the API key nor the URL's password is in any file of the out
    folder (results.sqlite, episodes.csv, report.html, config.json, ...) or on stdout / stderr."""
    import base64

    secret = "sk-e2e-5f0c1d2e3a4b" if case == "key" else "pw-e2e-9a8b7c6d"
    secrets = [secret, base64.b64encode(f"alice:{secret}".encode()).decode()]
    host = f"127.0.0.1:{server.port}" if case == "key" else f"alice:{secret}@127.0.0.1:{server.port}"
    spec = f"llm:smollm2@http://{host}/v1" + ("?key_env=ICR_E2E_KEY" if case == "key" else "")
    server.echo = 500
    server.models_reply = (200, b'{"data": [{"id": "smollm2"}]}', "application/json")
    out = tmp_path / "out"
    proc = _evaluate(suite, out, spec, env={"ICR_E2E_KEY": secret})
    assert proc.returncode == 0, proc.stderr.decode()[-2000:]
    said = {h.get("Authorization") for h in server.headers}
    assert said == {f"Bearer {secret}" if case == "key" else f"Basic {secrets[1]}"}
    messages = _messages(out)
    assert len(messages) == 2 and all("HTTP 500: invalid key" in m and "***" in m for m in messages)
    assert (out / "report.html").is_file() and (out / "episodes.csv").is_file()
    assert _leaks(out, proc, secrets) == []
    # refused at planning time, the answer quoting the key: one line, no key, nothing written
    server.echo = 401
    again = tmp_path / "again"
    proc = _evaluate(suite, again, spec, env={"ICR_E2E_KEY": secret})
    assert proc.returncode == 2 and b"HTTP 401: invalid key" in proc.stderr and not again.exists()
    assert _leaks(tmp_path, proc, secrets) == []


@pytest.mark.sumo
def test_a_page_instead_of_answers_crashes_episodes_and_the_right_server_repairs_them(suite, server,
                                                                                     tmp_path):
    server.replies, server.content_type = [(200, PAGE, 0.0)], "text/html"
    server.models_reply = (200, b'{"data": [{"id": "smollm2"}]}', "application/json")
    out = tmp_path / "out"
    spec = f"llm:smollm2@{server.endpoint}"
    proc = _evaluate(suite, out, spec)
    assert proc.returncode == 0, proc.stderr.decode()[-2000:]
    assert all("answered HTTP 200 with text/html" in m and "not an OpenAI-compatible JSON answer" in m
               for m in _messages(out))
    assert len(ResponseCache(out / "llm-cache")) == 0   # nothing stored as the model's answer
    server.replies, server.content_type = [(200, _chat('{"maneuver": "follow"}'), 0.0)], "application/json"
    proc = _evaluate(suite, out, spec, "--retry-crashed")
    assert proc.returncode == 0 and _messages(out) == ["", ""]
    assert len(ResponseCache(out / "llm-cache")) >= 1
    # a URL whose /models is a web page is refused before any episode runs
    server.models_reply = (200, PAGE, "text/html")
    proc = _evaluate(suite, tmp_path / "other", spec)
    line = proc.stderr.decode().strip()
    assert proc.returncode == 2 and "\n" not in line and "not an OpenAI-compatible JSON answer" in line
    assert not (tmp_path / "other").exists()


@pytest.mark.sumo
def test_a_password_in_a_remote_url_is_never_stored_or_printed(suite, tmp_path):
    from icrsumo.agents.hosting.serve import AgentServer

    agents = Path(__file__).parents[1] / "data" / "agents" / "user_agents.py"
    srv = AgentServer(f"{agents}:BevKeeper").start()
    try:
        port = srv.url.rsplit(":", 1)[1]
        out = tmp_path / "out"
        proc = _evaluate(suite, out, f"remote:http://alice:pw-remote-31337@127.0.0.1:{port}", "--quiet")
    finally:
        srv.shutdown()
    assert proc.returncode == 0, proc.stderr.decode()[-2000:]
    assert f"remote:http://alice:***@127.0.0.1:{port}" in (out / "config.json").read_text()
    assert _leaks(out, proc, ["pw-remote-31337"]) == []


def test_an_unwritable_cache_stops_the_run_before_anything_is_written(server, tmp_path, capsys):
    from icrsumo.app.cli.main import main

    out = tmp_path / "out"
    out.mkdir()
    (out / "llm-cache").write_text("a file where the cache folder goes")
    code = main(["evaluate", "--suite", "tiny", "--routes", "tiny_003", "--k", "1", "--quiet",
                 "--out", str(out), "--agent", f"llm:smollm2@{server.endpoint}"])
    line = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in line and "Traceback" not in line
    assert f"{out / 'llm-cache'}: the LLM response cache cannot be written: " in line
    assert sorted(p.name for p in out.iterdir()) == ["llm-cache"]


def test_an_api_key_that_is_not_printable_ascii_is_one_line_never_shown(monkeypatch):
    monkeypatch.setenv("ICRSUMO_TEST_KEY", "sk-clé-secrète")
    with pytest.raises(InputError) as err:
        api_key(LLMSettings("smollm2", "http://127.0.0.1:1/v1", key_env="ICRSUMO_TEST_KEY"))
    line = err.value.line()
    assert "ICRSUMO_TEST_KEY" in line and "not printable ASCII (character 6 of 14)" in line
    assert "secr" not in line and "\n" not in line


# --------------------------------------------------------------------------- asking for clarification
def test_with_asking_on_the_model_may_answer_ask_and_only_then():
    from icrsumo.agents.llm import SCHEMA_ASKING, SYSTEM, SYSTEM_ASKING

    s = LLMSettings("m", "http://127.0.0.1:1/v1")
    plain, asking = build_request(s, "x", SCENE), build_request(s, "x", SCENE, asking=True)
    assert (plain["messages"][0]["content"], plain["response_format"]["schema"]) == (SYSTEM, SCHEMA)
    assert asking["messages"][0]["content"] == SYSTEM_ASKING
    assert asking["response_format"]["schema"] == SCHEMA_ASKING
    assert "ask = " in SYSTEM_ASKING and "stop, ask>" in SYSTEM_ASKING and "ask =" not in SYSTEM
    enum = SCHEMA["properties"]["maneuver"]["enum"]
    assert SCHEMA_ASKING["properties"]["maneuver"]["enum"] == [*enum, "ask"] and "ask" not in enum
    assert request_hash(plain) != request_hash(asking)   # cached apart
    assert parse_answer('{"maneuver": "Ask"}', asking=True) is Intent.UNKNOWN
    with pytest.raises(Invalid, match="not on the menu"):
        parse_answer('{"maneuver": "ask"}')


@pytest.mark.sumo
def test_an_llm_agent_answering_ask_asks_the_navigator_and_reads_its_answer(cache, server):
    """tiny_003, ambiguity k=0, asking on, a model that answers "ask" first and "left" after: the
    agent asks the navigator, the exchange is stored with maneuver unknown, the navigator's answer
    (the baseline's turn instruction) goes to the model, and the route is completed."""
    from icrsumo.agents.llm import LLMFollower
    from icrsumo.evaluation.bundled import bundled_route
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.scoring import score_episode
    from icrsumo.sim.episode import RunOptions, run_episode
    from icrsumo.world.scenario import read_scenario

    sc_dir, instr = bundled_route("tiny_003")
    sets = {(s.family, s.k): s for s in read_instruction_sets(instr)}
    base = sets[("baseline", 0)]
    server.replies = [(200, _chat('{"maneuver": "ask"}'), 0.0), (200, _chat('{"maneuver": "left"}'), 0.0)]
    agent = LLMFollower(LLMSettings("smollm2", server.endpoint))
    log = run_episode(read_scenario(sc_dir), sets[("ambiguity", 0)], agent, RunOptions(asking=True),
                      baseline=base)
    first = log.model_calls[0]
    assert (first.maneuver, first.valid) == (Intent.UNKNOWN, True)
    assert json.loads(first.answer) == {"maneuver": "ask"}
    assert log.asks and log.asks[0].answered and log.asks[0].t == first.t
    turn = next(i for i in base.instructions if i.maneuver_pos is not None)
    told = [c for c in log.model_calls[1:] if json.dumps(turn.rendered()) in c.prompt]
    assert told and told[0].maneuver is Intent.LEFT
    assert score_episode(log).termination == "completed"
