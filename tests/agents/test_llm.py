"""The LLM interpreter without SUMO: its spec, request, answer parsing, response cache and the
client's answers to a server that misbehaves (a small HTTP server on 127.0.0.1 that sends what
each test tells it to: malformed, empty, huge or late answers, errors, nothing at all)."""

from __future__ import annotations

import json
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
    build_request,
    check_server,
    parse_answer,
    parse_spec,
    with_options,
)
from icrsumo.agents.registry import agent_factory
from icrsumo.agents.remote import free_port
from icrsumo.errors import InputError
from icrsumo.llmio import Invalid, ResponseCache, request_hash
from icrsumo.types import Intent

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
    (status, body bytes, delay s) used in turn (the last one repeats)."""

    def __init__(self) -> None:
        self.replies: list[tuple[int, bytes, float]] = [(200, b"{}", 0.0)]
        self.models: list[str] | None = ["smollm2"]
        self.hits = 0
        owner = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):  # quiet
                pass

            def _send(self, status: int, body: bytes) -> None:
                self.send_response(status)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def do_GET(self):
                if owner.models is None:
                    self._send(404, b'{"error": "no such path"}')
                else:
                    self._send(200, json.dumps({"data": [{"id": m} for m in owner.models]}).encode())

            def do_POST(self):
                self.rfile.read(int(self.headers.get("Content-Length", 0)))
                status, body, delay = owner.replies[min(owner.hits, len(owner.replies) - 1)]
                owner.hits += 1
                time.sleep(delay)
                self._send(status, body)

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.endpoint = f"http://127.0.0.1:{self.httpd.server_address[1]}/v1"
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


def _ask(server, tmp_path: Path | None = None, **kw):
    settings = LLMSettings("smollm2", server.endpoint, cache_dir=tmp_path, **kw)
    return Asker(settings).ask(build_request(settings, "Turn left at the junction.", SCENE))


@pytest.mark.parametrize("reply, problem", [
    (b"<html>oops</html>", "response body is not JSON"),
    (b'{"choices": []}', "no choices[0]"),
    (_chat(""), "no choices[0].message.content"),
    (_chat("I would turn left."), "answer is not JSON"),
    (_chat('{"maneuver": "fly"}'), "not on the menu"),
    (_chat("x" * 100_000), "response larger than"),
])
def test_malformed_empty_huge_or_prose_answers_are_invalid_never_a_crash(server, reply, problem):
    server.replies = [(200, reply, 0.0)]
    key, answer = _ask(server)
    assert not answer.valid and answer.maneuver == Intent.FOLLOW and problem in answer.problem


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
