"""The ``llm`` guard: its request and answer parsing (no model), and real closed-loop episodes
with SmolLM2 on llama.cpp's server, replayed from the response cache with the server gone."""

from __future__ import annotations

import json
import shutil

import pytest

from icrsumo.agents.remote import free_port
from icrsumo.app.api import evaluate
from icrsumo.core.errors import InputError
from icrsumo.core.types import Intent
from icrsumo.core.vocab import Verdict
from icrsumo.guards.base import GuardContext, NavPlan, PlanStep
from icrsumo.guards.llm import build_request, llm_guard_factory, parse_verdict, question
from icrsumo.results.store import ResultStore

ROUTES = ["tiny_000"]


def test_the_question_holds_the_instruction_the_previous_one_and_the_plan():
    step = PlanStep("turn_left", Intent.LEFT, 40.0, "traffic_light", (Intent.LEFT, Intent.RIGHT))
    plan = NavPlan(10.0, (step,))
    ctx = GuardContext(t=1.0, progress=10.0, instruction_id=2, previous="Follow the road.", plan=plan)
    q = question("Police order: turn right.", ctx)
    assert "New instruction: Police order: turn right." in q and "Previous instruction: Follow the road." in q
    assert "in 40 m: left at the traffic light (branches: left, right)" in q
    body = build_request(llm_guard_factory("llm:m@http://127.0.0.1:9/v1").settings, "Turn left.", ctx)
    assert body["temperature"] == 0 and body["response_format"]["schema"]["properties"]["verdict"]["enum"] \
        == ["pass", "block"]


@pytest.mark.parametrize(("record", "verdict"), [
    ({"content": '{"verdict": "block"}'}, Verdict.BLOCK),
    ({"content": ' {"verdict": "Pass"} '}, Verdict.PASS),
    ({"content": "block"}, None), ({"content": '{"verdict": "maybe"}'}, None), ({"content": "[1]"}, None),
    ({"content": None, "problem": "timed out"}, None)])
def test_answers_that_are_not_a_verdict_are_problems(record, verdict):
    got, problem = parse_verdict(record)
    assert got == verdict and (problem == "") == (verdict is not None)


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
    assert log.guard and all(d.reason in ("model: pass", "model: block") for d in log.guard)
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
