"""The ``llm`` guard: its request and how it reads answers (a real HTTP server on 127.0.0.1 that
answers what a test sets), SmolLM2 on llama.cpp's server reading instructions through the
schema, and real closed-loop episodes replayed from the response cache with the server gone."""

from __future__ import annotations

import json
import shutil
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from icrsumo.agents.llm import MENU
from icrsumo.agents.remote import free_port
from icrsumo.app.api import evaluate
from icrsumo.core.errors import InputError
from icrsumo.core.types import Intent
from icrsumo.core.vocab import Verdict
from icrsumo.guards.base import GuardContext, NavPlan, PlanStep
from icrsumo.guards.llm import KEY, build_request, llm_guard_factory
from icrsumo.results.store import ResultStore

ROUTES = ["tiny_000"]
LEFT = NavPlan(10.0, (PlanStep("turn_left", Intent.LEFT, 40.0, "traffic_light", (Intent.LEFT,)),))
INVALID = "invalid answer, passed"
BLOCKED = "model read right, but the plan goes left in 40 m"


def _ctx(plan: NavPlan | None = LEFT) -> GuardContext:
    return GuardContext(t=1.0, progress=10.0, instruction_id=2, previous="Follow the road.", plan=plan)


def test_the_question_names_the_planned_maneuver_and_asks_for_the_instructions_one():
    settings = llm_guard_factory("llm:m@http://127.0.0.1:9/v1").settings
    body = build_request(settings, "Police order: turn right.", LEFT)
    system, user = (m["content"] for m in body["messages"])
    assert system.endswith("The planned maneuver is left.")
    assert user == 'Instruction: "Police order: turn right."'
    assert body["temperature"] == 0 and body["max_tokens"] >= 32
    assert body["response_format"]["schema"]["properties"][KEY]["enum"] == [m.value for m in MENU]
    none_left = build_request(settings, "Turn left.", NavPlan(90.0, ()))["messages"][0]["content"]
    assert none_left.endswith("The planned maneuver is follow.")
    # no schema to constrain the answer: the system message spells it out
    unconstrained = llm_guard_factory("llm:m@http://127.0.0.1:9/v1?format=none").settings
    bare = build_request(unconstrained, "Turn left.", LEFT)
    assert "response_format" not in bare and bare["messages"][0]["content"].endswith(
        'The planned maneuver is left. Answer with one JSON object and nothing else: '
        '{"instruction_maneuver": "<one of follow, left, right, straight, lane_left, lane_right, stop>"}.')


class _Answers:
    """An OpenAI-compatible server on 127.0.0.1 that answers every chat request with ``content``."""

    def __init__(self) -> None:
        self.content = ""
        owner = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):  # quiet
                pass

            def do_GET(self):
                self._send(json.dumps({"data": [{"id": "m"}]}).encode())

            def do_POST(self):
                self.rfile.read(int(self.headers.get("Content-Length", 0)))
                answer = {"message": {"role": "assistant", "content": owner.content}, "finish_reason": "stop"}
                self._send(json.dumps({"choices": [answer]}).encode())

            def _send(self, body: bytes) -> None:
                self.send_response(200)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.spec = f"llm:m@http://127.0.0.1:{self.httpd.server_address[1]}/v1"
        threading.Thread(target=self.httpd.serve_forever, daemon=True).start()


@pytest.fixture()
def answers():
    server = _Answers()
    yield server
    server.httpd.shutdown()
    server.httpd.server_close()


@pytest.mark.parametrize(("content", "ruling"), [
    ('{"instruction_maneuver": "right"}', (Verdict.BLOCK, BLOCKED)),
    ('{"instruction_maneuver": " Left"}', (Verdict.PASS, "model read left")),
    ("I would turn right.", (Verdict.PASS, f"{INVALID} (answer is not JSON)")),
    ('{"instruction_maneuver": "maybe"}', (Verdict.PASS, f"{INVALID} ({KEY} 'maybe' is not on the menu)")),
    ('{"verdict": "block"}', (Verdict.PASS, f"{INVALID} ({KEY} 'None' is not on the menu)")),
    ("", (Verdict.PASS, f"{INVALID} (answer is empty)")),
    ("[1]", (Verdict.PASS, f"{INVALID} ({KEY} 'None' is not on the menu)"))])
def test_the_answer_is_checked_against_the_plan_and_a_bad_one_passes_saying_why(answers, content, ruling):
    answers.content = content
    guard = llm_guard_factory(answers.spec)()
    assert guard.check("Police order: turn right.", _ctx()) == ruling


def test_a_bad_answers_reason_is_one_line_and_no_plan_or_no_text_asks_nothing(answers):
    answers.content = '{"instruction_maneuver":\n "fly\naway"}'
    guard = llm_guard_factory(answers.spec)()
    verdict, reason = guard.check("Turn left.", _ctx())
    assert verdict is Verdict.PASS and "\n" not in reason and reason.startswith(f"{INVALID} (")
    assert guard.check("  ", _ctx()) == (Verdict.PASS, "")
    assert guard.check("Turn left.", _ctx(None)) == (Verdict.PASS, "")
    assert guard.asker.sent == 1


#: (instruction, planned step) -> the ruling SmolLM2 is expected to answer with a valid JSON
SMOLLM2_CASES = [
    ("Turn left at the traffic light.", LEFT),
    ("Police order: turn right at the next junction.", LEFT),
    ("Move into the right lane within 50 meters.",
     NavPlan(0.0, (PlanStep("lane_change_right", Intent.LANE_RIGHT, 50.0),
                   PlanStep("turn_right", Intent.RIGHT, 120.0, "priority", (Intent.RIGHT,))))),
    ("Keep following this road.", NavPlan(300.0, ())),
]


def test_smollm2_answers_the_schema_and_the_cache_replays_it_without_the_server(smollm2, tmp_path):
    factory = llm_guard_factory(smollm2.spec()).bind(tmp_path)
    guard = factory()
    rulings = [guard.check(text, _ctx(plan)) for text, plan in SMOLLM2_CASES]
    # every answer was read (the schema and the answer's token budget fit), none failed open
    assert all(reason.startswith("model read ") for _, reason in rulings), rulings
    assert guard.asker.sent == len(SMOLLM2_CASES)
    dead = llm_guard_factory(f"llm:smollm2@http://127.0.0.1:{free_port()}/v1").bind(tmp_path)
    again = dead()
    assert [again.check(text, _ctx(plan)) for text, plan in SMOLLM2_CASES] == rulings
    assert again.asker.sent == 0 and factory.fingerprint == dead.fingerprint


def test_a_bad_llm_guard_spec_names_the_guards_field():
    with pytest.raises(InputError, match="^guards: llm:nourl: an llm spec needs a model and a server URL"):
        llm_guard_factory("llm:nourl")


@pytest.mark.sumo
def test_the_llm_guard_asks_the_model_and_replays_from_the_cache(smollm2, tmp_path):
    out = tmp_path / "a"
    res = evaluate(agents="instruction-follower", guards=smollm2.spec(), families="misleading", k=1,
                   routes=ROUTES, out=out, workers=1)
    row = "instruction-follower+guard:llm:smollm2"
    assert res.crashed == 0 and row in res.summary["agents"]
    with ResultStore(out / "results.sqlite") as store:
        log = store.episode_log(row, ROUTES[0], "misleading", 0, 2026)
    assert log.guard and all(d.reason.startswith("model read ") for d in log.guard)
    doc = json.loads((out / "guard.json").read_text())
    assert doc["guards"]["llm:smollm2"]["detection"] is not None
    assert list((out / "llm-cache").glob("??/*.json"))
    again = tmp_path / "b"
    again.mkdir()
    for part in ("scenarios", "instructions", "llm-cache"):
        shutil.copytree(out / part, again / part)
    dead = f"llm:smollm2@http://127.0.0.1:{free_port()}/v1"
    res2 = evaluate(agents="instruction-follower", guards=dead, families="misleading", k=1, routes=ROUTES,
                    out=again, workers=2)
    assert res2.crashed == 0
    for name in ("summary.json", "guard.json"):
        assert (again / name).read_bytes() == (out / name).read_bytes(), name
