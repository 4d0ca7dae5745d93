"""LLM variants against a scripted OpenAI-compatible chat-completions server on 127.0.0.1."""

from __future__ import annotations

import json
import re
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from icrsumo.core.types import Instruction, InstructionSet, Intent, Notice
from icrsumo.instructions import llm
from icrsumo.instructions.intent import classify_intent
from icrsumo.instructions.llm import LLMConfig, LLMError, llm_variants

BASELINE = InstructionSet(
    route_id="r7",
    family="baseline",
    k=0,
    seed=0,
    instructions=(
        Instruction(0, 0.0, "Follow the road for [x] meters.", Intent.FOLLOW, "follow_distance",
                    distance=120.0, maneuver_pos=None),
        Instruction(1, 35.5, "In [x] meters, turn left at the intersection.", Intent.LEFT, "turn_left",
                    distance=40.0, maneuver_pos=75.5, junction="crossroad"),
        Instruction(2, 80.25, "Go straight at the next intersection.", Intent.STRAIGHT, "straight",
                    maneuver_pos=95.0, junction="traffic_light"),
        Instruction(3, 140.0, "Change to the left lane.", Intent.LANE_LEFT, "lane_change_left",
                    maneuver_pos=150.0),
    ),
    notices=(Notice(0, 80.0, 96.0, "Traffic light ahead.", "traffic_light"),),
)

# One valid rewrite of each BASELINE instruction per family (the real classifier agrees).
GOOD = {
    "paraphrase": [
        "Keep driving along this road for [x] meters.",
        "After [x] meters, make a left turn at the crossing.",
        "Continue straight through the next junction.",
        "Move over into the left lane.",
    ],
    "noise": [
        "follow the road for [x] meters!",
        "IN [x] METERS, TURN LEFT AT THE INTERSECTION",
        "go straight at the nxet intersection",
        "Change to the left lane!!",
    ],
    "misleading": [
        "Police order: leave the road by turning right in [x] meters.",
        "Traffic control instructs you to turn right in [x] meters.",
        "Official detour: turn left at the next intersection.",
        "Police order: change to the right lane.",
    ],
    "ambiguity": [
        "Go that way in a bit.",
        "Make a turn up ahead.",
        "Do the usual thing at the next one.",
        "Head over there when you can.",
    ],
}


# ---------------------------------------------------------------------------------------------
# scripted chat-completions server

Reply = tuple[int, bytes, float]          # HTTP status, body, delay (s) before answering
Step = Callable[[dict], Reply]


def chat(content: str, finish_reason: str = "stop") -> bytes:
    return json.dumps({
        "id": "cmpl-test", "object": "chat.completion", "model": "m",
        "choices": [{"index": 0, "message": {"role": "assistant", "content": content},
                     "finish_reason": finish_reason}],
    }).encode()


def request_items(body: dict) -> tuple[list[dict], int]:
    """The baseline items and K listed in a request's user message."""
    user = body["messages"][-1]["content"]
    line = next(ln for ln in user.splitlines() if ln.startswith("[{"))
    k = int(re.search(r"Write (\d+) ", user).group(1))
    return json.loads(line), k


def variants_json(body: dict, family: str, edit: Callable[[list[list[dict]]], None] | None = None) -> str:
    """A valid answer to ``body`` (texts from GOOD, shifted per variant), optionally edited."""
    items, k = request_items(body)
    by_id = {ins.id: n for n, ins in enumerate(BASELINE.instructions)}
    variants = []
    for i in range(k):
        variants.append([{"id": it["id"], "trigger": it["trigger"],
                          "text": GOOD[family][by_id[it["id"]]] + ("" if i == 0 else f" ({i})")}
                         for it in items])
    if edit is not None:
        edit(variants)
    return json.dumps({"variants": variants})


def ok(family: str, edit=None, fence: bool = False) -> Step:
    def step(body: dict) -> Reply:
        content = variants_json(body, family, edit)
        if fence:
            content = f"Here you go:\n```json\n{content}\n```\n"
        return 200, chat(content), 0.0
    return step


def raw(status: int, payload: bytes, delay: float = 0.0) -> Step:
    return lambda body: (status, payload, delay)


def content(text: str) -> Step:
    return lambda body: (200, chat(text), 0.0)


class FakeLLM:
    def __init__(self) -> None:
        self.script: deque[Step] = deque()
        self.requests: list[dict] = []
        self.headers: list[dict] = []
        self.paths: list[str] = []
        self.lock = threading.Lock()
        fake = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args) -> None:
                pass

            def do_POST(self) -> None:
                n = int(self.headers.get("Content-Length", "0"))
                body = json.loads(self.rfile.read(n))
                with fake.lock:
                    fake.requests.append(body)
                    fake.headers.append(dict(self.headers))
                    fake.paths.append(self.path)
                    step = fake.script.popleft() if fake.script else raw(500, b'{"error": "script empty"}')
                if self.path != "/v1/chat/completions":
                    step = raw(404, b'{"error": {"message": "no such route"}}')
                status, payload, delay = step(body)
                time.sleep(delay)
                try:
                    self.send_response(status)
                    self.send_header("Content-Type", "application/json")
                    self.send_header("Content-Length", str(len(payload)))
                    self.end_headers()
                    self.wfile.write(payload)
                except (BrokenPipeError, ConnectionResetError):
                    pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.endpoint = f"http://127.0.0.1:{self.server.server_address[1]}/v1"
        self.thread = threading.Thread(target=self.server.serve_forever, kwargs={"poll_interval": 0.05},
                                       daemon=True)

    def queue(self, *steps: Step) -> None:
        self.script.extend(steps)

    @property
    def count(self) -> int:
        return len(self.requests)


@pytest.fixture
def server():
    fake = FakeLLM()
    fake.thread.start()
    try:
        yield fake
    finally:
        fake.server.shutdown()
        fake.server.server_close()
        fake.thread.join(timeout=5)
        assert not fake.thread.is_alive()


@pytest.fixture(autouse=True)
def no_backoff(monkeypatch):
    monkeypatch.setattr(llm, "RETRY_BACKOFF", 0.0)


def cfg_for(server: FakeLLM, tmp_path, **kw) -> LLMConfig:
    kw.setdefault("timeout", 5.0)
    return LLMConfig(endpoint=server.endpoint, model="test-model", cache_dir=tmp_path / "cache", **kw)


def cache_files(tmp_path) -> list:
    root = tmp_path / "cache"
    return sorted(root.rglob("*.json")) if root.exists() else []


def run(server, tmp_path, family="paraphrase", k=2, seed=3, **kw):
    return llm_variants(BASELINE, family, k, seed, cfg_for(server, tmp_path, **kw), classify=classify_intent)


# ---------------------------------------------------------------------------------------------
# the fixture texts themselves


def test_fixture_texts_classify_as_intended():
    for n, base in enumerate(BASELINE.instructions):
        assert classify_intent(base.text) == base.intent, base.text
        assert classify_intent(GOOD["paraphrase"][n]) == base.intent
        assert classify_intent(GOOD["noise"][n]) == base.intent
        assert classify_intent(GOOD["misleading"][n]) in llm.CONTRADICTS[base.intent]
        assert classify_intent(GOOD["ambiguity"][n]) == Intent.UNKNOWN


# ---------------------------------------------------------------------------------------------
# valid answers, request format, cache


@pytest.mark.parametrize("family", llm.FAMILIES)
def test_valid_answer_gives_k_variant_sets(server, tmp_path, family):
    server.queue(ok(family))
    out = run(server, tmp_path, family=family, k=2, seed=11)
    assert server.count == 1
    assert len(out) == 2
    key = llm.request_hash(server.requests[0])
    for i, vs in enumerate(out):
        assert (vs.route_id, vs.family, vs.k, vs.seed) == ("r7", family, i, 11)
        assert vs.notices == BASELINE.notices
        assert len(vs.instructions) == len(BASELINE.instructions)
        for n, (var, base) in enumerate(zip(vs.instructions, BASELINE.instructions)):
            suffix = "" if i == 0 else f" ({i})"
            assert var.text == GOOD[family][n] + suffix
            assert var.source == base.text
            assert var.template == f"llm:test-model:{key[:12]}:{i}"
            for field in ("id", "trigger", "intent", "type", "distance", "maneuver_pos", "junction"):
                assert getattr(var, field) == getattr(base, field), field


def test_request_body_and_headers(server, tmp_path):
    server.queue(ok("misleading"))
    run(server, tmp_path, family="misleading", k=1, seed=42, temperature=0.3, api_key="sk-test")
    body = server.requests[0]
    assert server.paths == ["/v1/chat/completions"]
    assert body["model"] == "test-model"
    assert body["seed"] == 42
    assert body["temperature"] == 0.3
    assert body["response_format"] == {"type": "json_object"}
    roles = [m["role"] for m in body["messages"]]
    assert roles == ["system", "user"]
    system, user = (m["content"] for m in body["messages"])
    assert "misleading" in system.lower() and '"variants"' in system
    items, k = request_items(body)
    assert k == 1
    assert items == [{"id": b.id, "trigger": b.trigger, "text": b.text, "intent": b.intent.value}
                     for b in BASELINE.instructions]
    assert server.headers[0]["Authorization"] == "Bearer sk-test"
    assert server.headers[0]["Content-Type"] == "application/json"
    # the key is never part of the request body (nor of the cache)
    assert "sk-test" not in json.dumps(body)
    assert "sk-test" not in cache_files(tmp_path)[0].read_text()


def test_no_api_key_no_authorization_header(server, tmp_path):
    server.queue(ok("paraphrase"))
    run(server, tmp_path, k=1)
    assert "Authorization" not in server.headers[0]


def test_cache_hit_makes_no_request(server, tmp_path):
    server.queue(ok("paraphrase"))
    first = run(server, tmp_path, k=2, seed=5)
    assert server.count == 1
    key = llm.request_hash(server.requests[0])
    path = tmp_path / "cache" / key[:2] / f"{key}.json"
    assert cache_files(tmp_path) == [path]
    rec = json.loads(path.read_text())
    assert rec["key"] == key and rec["request"] == server.requests[0]
    assert json.loads(rec["content"])["variants"][0][0]["text"] == GOOD["paraphrase"][0]
    again = run(server, tmp_path, k=2, seed=5)
    assert server.count == 1            # served from the cache
    assert again == first
    # another seed, K or family is another request
    server.queue(ok("paraphrase"))
    run(server, tmp_path, k=2, seed=6)
    assert server.count == 2
    assert len(cache_files(tmp_path)) == 2


def test_cache_used_offline(server, tmp_path):
    server.queue(ok("noise"))
    first = run(server, tmp_path, family="noise", k=1)
    cfg = LLMConfig(endpoint=f"http://127.0.0.1:{free_port()}/v1", model="test-model",
                    cache_dir=tmp_path / "cache", timeout=2.0)
    assert llm_variants(BASELINE, "noise", 1, 3, cfg, classify=classify_intent) == first


def test_corrupt_cache_entry_is_refetched(server, tmp_path):
    server.queue(ok("paraphrase"), ok("paraphrase"))
    run(server, tmp_path, k=1)
    (path,) = cache_files(tmp_path)
    path.write_text("{not json")
    run(server, tmp_path, k=1)
    assert server.count == 2
    assert json.loads(path.read_text())["key"] == path.stem


def test_fenced_json_is_accepted(server, tmp_path):
    server.queue(ok("ambiguity", fence=True))
    out = run(server, tmp_path, family="ambiguity", k=2)
    assert server.count == 1
    assert out[0].instructions[1].text == GOOD["ambiguity"][1]
    assert len(cache_files(tmp_path)) == 1


def test_ambiguity_may_drop_or_keep_placeholder(server, tmp_path):
    def keep(v):
        v[0][1]["text"] = "Do it in [x] meters."
    server.queue(ok("ambiguity", keep))
    out = run(server, tmp_path, family="ambiguity", k=1)
    assert out[0].instructions[1].text == "Do it in [x] meters."
    assert "[x]" not in out[0].instructions[0].text


def test_default_classifier_is_the_real_one(server, tmp_path):
    server.queue(ok("paraphrase"))
    out = llm_variants(BASELINE, "paraphrase", 1, 0, cfg_for(server, tmp_path))
    assert out[0].instructions[1].text == GOOD["paraphrase"][1]


# ---------------------------------------------------------------------------------------------
# invalid answers: retried with the problem fed back, never cached


def _set(v, i, n, key, value):
    v[i][n][key] = value


def para(i: int, n: int, key: str, value) -> Step:
    """A paraphrase answer with variant ``i``, item ``n``, field ``key`` set to ``value``."""
    return ok("paraphrase", lambda v: _set(v, i, n, key, value))


def para_edit(fn) -> Step:
    return ok("paraphrase", fn)


OOM = b'{"error": {"message": "CUDA out of memory"}}'
BAD = {   # case -> (step factory, problem text expected in the feedback / error)
    "malformed_json": (lambda: content('{"variants": [[{"id": 0, '), "not JSON"),
    "not_an_object": (lambda: content("[1, 2]"), 'key "variants"'),
    "no_variants_key": (lambda: content('{"answers": []}'), 'no "variants" list'),
    "wrong_variant_count": (lambda: para_edit(lambda v: v.pop()), "1 variant list(s), expected exactly 2"),
    "missing_item": (lambda: para_edit(lambda v: v[1].pop()), "variant 1 has 3 item(s), expected 4"),
    "changed_trigger": (lambda: para(0, 2, "trigger", 81.0), "id 2: trigger 81.0 changed, expected 80.25"),
    "trigger_not_number": (lambda: para(0, 2, "trigger", "80.25"), "trigger '80.25' changed"),
    "changed_id_order": (lambda: para_edit(lambda v: v[0].reverse()),
                         "ids [3, 2, 1, 0], expected [0, 1, 2, 3]"),
    "dropped_placeholder": (lambda: para(1, 0, "text", "Keep driving along this road."),
                            "lost the placeholder [x]"),
    "added_placeholder": (lambda: para(0, 3, "text", "In [x] m move into the left lane."),
                          "adds the placeholder [x]"),
    "intent_flip": (lambda: para(0, 1, "text", "In [x] meters, turn right at the crossing."),
                    "reads as right, expected left"),
    "empty_text": (lambda: para(0, 3, "text", "   "), "id 3: text is empty"),
    "text_not_string": (lambda: para(0, 3, "text", None), "id 3: text is empty"),
    "too_long": (lambda: para(0, 2, "text", "Go straight " + "x" * 300), "must be under 300"),
    "multi_line": (lambda: para(0, 2, "text", "Go straight.\nNow."), "one line"),
    "unchanged_paraphrase": (lambda: para(0, 2, "text", BASELINE.instructions[2].text),
                             "repeats the original wording"),
    "http_500": (lambda: raw(500, OOM), "HTTP 500: CUDA out of memory"),
    "http_200_not_json": (lambda: raw(200, b"<html>oops</html>"),
                          "not an OpenAI-compatible JSON answer (the body is not JSON)"),
    "no_choices": (lambda: raw(200, b'{"choices": []}'),
                   "not an OpenAI-compatible JSON answer (no choices[0])"),
    "null_content": (lambda: raw(200, b'{"choices": [{"message": {"content": null}}]}'),
                     "answer content is empty"),
    "truncated": (lambda: lambda body: (200, chat(variants_json(body, "paraphrase")[:40], "length"), 0.0),
                  "truncated (finish_reason=length)"),
}


#: answers that are no OpenAI-compatible answer at all: never the model's, never fed back to it
SERVER_FAULTS = ("http_500", "http_200_not_json", "no_choices")


@pytest.mark.parametrize("case", sorted(BAD))
def test_invalid_answer_is_retried_then_valid_used(server, tmp_path, case):
    bad, problem = BAD[case]
    server.queue(bad(), ok("paraphrase"))
    out = run(server, tmp_path, family="paraphrase", k=2)
    assert server.count == 2
    assert [i.text for i in out[0].instructions] == GOOD["paraphrase"]
    retry_user = server.requests[1]["messages"][-1]["content"]
    if case in SERVER_FAULTS:        # a transport failure or a server fault resends the same request
        assert server.requests[1] == server.requests[0]
    else:                            # the problem is fed back to the model
        assert "previous answer was rejected" in retry_user and problem in retry_user
        assert server.requests[1]["messages"][0] == server.requests[0]["messages"][0]
    # the valid answer is cached under the FIRST request's hash
    key = llm.request_hash(server.requests[0])
    assert [p.stem for p in cache_files(tmp_path)] == [key]
    assert out[1].instructions[0].template == f"llm:test-model:{key[:12]}:1"
    # and a rerun is served from the cache
    assert run(server, tmp_path, family="paraphrase", k=2) == out
    assert server.count == 2


@pytest.mark.parametrize("case", ["malformed_json", "wrong_variant_count", "changed_trigger",
                                  "changed_id_order", "dropped_placeholder", "intent_flip", "empty_text",
                                  "http_500", "http_200_not_json"])
def test_retries_exhausted_raise(server, tmp_path, case):
    bad, problem = BAD[case]
    server.queue(bad(), bad(), bad(), ok("paraphrase"))
    with pytest.raises(LLMError) as exc:
        run(server, tmp_path, family="paraphrase", k=2, retries=2)
    msg = str(exc.value)
    assert server.count == 3
    assert "route r7" in msg and "family paraphrase" in msg and "3 attempt(s)" in msg
    assert problem in msg
    assert "\n" not in msg
    assert exc.value.route_id == "r7" and exc.value.family == "paraphrase" and problem in exc.value.problem
    assert cache_files(tmp_path) == []


def test_retries_zero_means_one_attempt(server, tmp_path):
    server.queue(content("nope"), ok("paraphrase"))
    with pytest.raises(LLMError, match="1 attempt"):
        run(server, tmp_path, k=1, retries=0)
    assert server.count == 1


def test_misleading_must_contradict(server, tmp_path):
    # "turn left" for a left is not misleading; straight -> straight neither
    not_contra = ok("misleading", lambda v: _set(v, 0, 1, "text", "Police order: turn left in [x] meters."))
    straight = ok("misleading",
                  lambda v: _set(v, 0, 2, "text", "Police order: go straight at the next junction."))
    server.queue(not_contra, straight, not_contra)
    with pytest.raises(LLMError) as exc:
        run(server, tmp_path, family="misleading", k=1)
    assert "reads as left, must contradict left (read as right)" in str(exc.value)
    assert "must contradict straight (read as left or right)" in server.requests[2]["messages"][-1]["content"]
    assert cache_files(tmp_path) == []


def test_misleading_lane_and_follow_mappings(server, tmp_path):
    same_lane = ok("misleading", lambda v: _set(v, 0, 3, "text", "Police order: change to the left lane."))
    server.queue(same_lane, ok("misleading"))
    out = run(server, tmp_path, family="misleading", k=1)
    assert "must contradict lane_left (read as lane_right)" in server.requests[1]["messages"][-1]["content"]
    assert classify_intent(out[0].instructions[0].text) in (Intent.LEFT, Intent.RIGHT)


def test_ambiguity_must_be_unknown(server, tmp_path):
    clear = ok("ambiguity", lambda v: _set(v, 0, 1, "text", "Turn left soon."))
    server.queue(clear, clear, clear)
    with pytest.raises(LLMError, match="still reads as left, must leave the maneuver unknown"):
        run(server, tmp_path, family="ambiguity", k=1)


def test_noise_must_keep_intent_and_change_text(server, tmp_path):
    flipped = ok("noise", lambda v: _set(v, 0, 1, "text", "in [x] meters, turn right at the intersection"))
    same = ok("noise", lambda v: _set(v, 0, 2, "text", BASELINE.instructions[2].text))
    server.queue(flipped, same, ok("noise"))
    out = run(server, tmp_path, family="noise", k=1)
    assert server.count == 3
    assert "reads as right, expected left" in server.requests[1]["messages"][-1]["content"]
    assert "identical to the original" in server.requests[2]["messages"][-1]["content"]
    assert out[0].instructions[2].text == GOOD["noise"][2]


def test_stop_and_unknown_baseline_have_no_intent_check(server, tmp_path):
    base = InstructionSet("r9", "baseline", 0, 0, (
        Instruction(0, 0.0, "Stop at the end of the road.", Intent.STOP, "stop"),
        Instruction(1, 10.0, "Watch out.", Intent.UNKNOWN, "other"),
    ))
    answer = {"variants": [[{"id": 0, "trigger": 0.0, "text": "Turn right here."},
                            {"id": 1, "trigger": 10, "text": "Turn left now."}]]}
    server.queue(content(json.dumps(answer)))
    cfg = cfg_for(server, tmp_path)
    out = llm_variants(base, "misleading", 1, 0, cfg, classify=classify_intent)
    assert [i.text for i in out[0].instructions] == ["Turn right here.", "Turn left now."]


# ---------------------------------------------------------------------------------------------
# transport


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_connection_refused_is_a_clear_error(tmp_path):
    endpoint = f"http://127.0.0.1:{free_port()}/v1"
    cfg = LLMConfig(endpoint=endpoint, model="m", cache_dir=tmp_path / "cache", timeout=2.0, retries=2)
    t0 = time.monotonic()
    with pytest.raises(LLMError) as exc:
        llm_variants(BASELINE, "paraphrase", 1, 0, cfg, classify=classify_intent)
    assert time.monotonic() - t0 < 5
    assert f"LLM endpoint {endpoint} unreachable (connection refused)" in str(exc.value)
    assert "route r7" in str(exc.value)
    assert cache_files(tmp_path) == []


def test_slow_answer_times_out_and_is_retried(server, tmp_path):
    server.queue(raw(200, chat("{}"), delay=1.0), ok("paraphrase"))
    t0 = time.monotonic()
    out = run(server, tmp_path, k=1, timeout=0.5)
    assert time.monotonic() - t0 < 3
    assert server.count == 2
    assert server.requests[1] == server.requests[0]
    assert out[0].instructions[0].text == GOOD["paraphrase"][0]


def test_slow_answers_exhaust_retries(server, tmp_path):
    slow = raw(200, chat("{}"), delay=1.0)
    server.queue(slow, slow)
    t0 = time.monotonic()
    with pytest.raises(LLMError, match="timed out"):
        run(server, tmp_path, k=1, timeout=0.5, retries=1)
    assert time.monotonic() - t0 < 4
    assert server.count == 2
    assert cache_files(tmp_path) == []


def test_client_error_is_not_retried(server, tmp_path):
    server.queue(raw(401, b'{"error": {"message": "invalid api key"}}'), ok("paraphrase"))
    with pytest.raises(LLMError, match="HTTP 401: invalid api key"):
        run(server, tmp_path, k=1)
    assert server.count == 1


def test_a_server_quoting_the_key_has_it_redacted(server, tmp_path):
    key = "sk-test-0123456789abcdef"
    quoted = json.dumps({"error": {"message": f"invalid api key Bearer {key}"}}).encode()
    server.queue(raw(401, quoted))
    with pytest.raises(LLMError) as err:
        run(server, tmp_path, k=1, api_key=key)
    assert "HTTP 401: invalid api key Bearer ***" in str(err.value) and key not in str(err.value)
    assert key not in err.value.problem


def test_rate_limit_is_retried(server, tmp_path):
    server.queue(raw(429, b'{"error": "slow down"}'), ok("paraphrase"))
    run(server, tmp_path, k=1)
    assert server.count == 2


def test_endpoint_forms(server, tmp_path):
    server.queue(ok("paraphrase"), ok("paraphrase"))
    for endpoint, seed in ((server.endpoint + "/", 1), (server.endpoint + "/chat/completions", 2)):
        cfg = LLMConfig(endpoint=endpoint, model="test-model", cache_dir=tmp_path / "cache", timeout=5.0)
        llm_variants(BASELINE, "paraphrase", 1, seed, cfg, classify=classify_intent)
    assert server.paths == ["/v1/chat/completions"] * 2


def test_bad_arguments(tmp_path):
    cfg = LLMConfig(endpoint="http://127.0.0.1:9/v1", model="m", cache_dir=tmp_path)
    with pytest.raises(ValueError, match="unknown family"):
        llm_variants(BASELINE, "sarcasm", 1, 0, cfg, classify=classify_intent)
    with pytest.raises(ValueError, match="positive integer"):
        llm_variants(BASELINE, "noise", 0, 0, cfg, classify=classify_intent)
    bad = LLMConfig(endpoint="127.0.0.1:8000/v1", model="m", cache_dir=tmp_path)
    with pytest.raises(LLMError, match="not an http"):
        llm_variants(BASELINE, "noise", 1, 0, bad, classify=classify_intent)


def test_empty_baseline_needs_no_request(tmp_path):
    cfg = LLMConfig(endpoint="http://127.0.0.1:9/v1", model="m", cache_dir=tmp_path)
    base = InstructionSet("r0", "baseline", 0, 0, ())
    out = llm_variants(base, "noise", 2, 0, cfg, classify=classify_intent)
    assert [(s.k, s.instructions) for s in out] == [(0, ()), (1, ())]
