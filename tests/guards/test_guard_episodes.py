"""Guards in real closed-loop episodes (SUMO, the instruction-follower): guarded rows beside the
unguarded ones, guard.json / guard.md / the figure, what the agent was shown, byte-identical
results whatever the worker count, and the errors: an unknown guard before any episode, a guard
that raises or answers nonsense as a crashed episode with the reason."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

import icrsumo
from icrsumo.guards.registry import GUARDS
from icrsumo.results.store import ResultStore

pytestmark = pytest.mark.sumo

ROUTES = ["tiny_000"]


def _run(out, workers):
    return icrsumo.evaluate(agents="instruction-follower", guards=["plan", "text"],
                            families=["misleading", "paraphrase"], k=1, routes=ROUTES, out=out,
                            workers=workers)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("guarded")
    return _run(out, 2)


def test_guarded_rows_their_reports_and_what_the_agent_was_shown(run):
    rows = set(run.summary["agents"])
    assert rows == {"instruction-follower", *(f"instruction-follower+guard:{g}" for g in ("plan", "text"))}
    doc = json.loads((run.out / "guard.json").read_text())
    assert doc["guards"]["plan"]["detection"] == 1.0 and doc["guards"]["plan"]["false_blocks"] == 0.0
    assert "text_holdout" in doc and (run.out / "figures" / "guard_tradeoff.png").stat().st_size > 1000
    assert "## instruction-follower+guard:plan" in (run.out / "guard.md").read_text()
    mis = doc["rows"]["instruction-follower+guard:plan"]["families"]["misleading"]
    assert mis["guarded"]["DS"] > mis["unguarded"]["DS"]
    with ResultStore(run.out / "results.sqlite") as store:
        log = store.episode_log("instruction-follower+guard:plan", "tiny_000", "misleading", 0, 2026)
        plain = store.episode_log("instruction-follower", "tiny_000", "misleading", 0, 2026)
    assert log.agent == "instruction-follower+guard:plan" and plain.guard == ()
    assert log.guard and all(d.verdict == "block" and d.reason for d in log.guard)
    assert set(log.instruction) == {-1}          # every instruction blocked: it was shown none
    assert max(plain.instruction) >= 0


def test_the_same_results_whatever_the_worker_count(run, tmp_path):
    again = _run(tmp_path / "again", 1)
    for name in ("summary.json", "guard.json", "guard.md", "results.md"):
        assert (again.out / name).read_bytes() == (run.out / name).read_bytes(), name


def test_an_unknown_guard_is_refused_before_anything_is_written(tmp_path):
    out = tmp_path / "o"
    p = subprocess.run([sys.executable, "-m", "icrsumo", "evaluate", "--guard", "nope", "--out", str(out),
                        "--routes", "tiny_000"], capture_output=True, text=True)
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1
    assert "--guard: nope: unknown guard" in p.stderr and "Traceback" not in p.stderr
    assert not out.exists()


class Raising:
    name, needs_plan = "raising", False

    def reset(self, info):
        pass

    def check(self, text, context):
        raise RuntimeError("the guard's model file is gone")


class Nonsense(Raising):
    name = "nonsense"

    def check(self, text, context):
        return "maybe"


def test_a_failing_guard_crashes_its_episodes_with_the_reason(tmp_path):
    messages = {"raising": "RuntimeError: the guard's model file is gone",
                "nonsense": "guard nonsense returned 'maybe', not pass / block"}
    for guard in (Raising, Nonsense):
        GUARDS.register(guard.name, guard)
    try:
        res = icrsumo.evaluate(agents="instruction-follower", guards=list(messages), families="misleading",
                               k=1, routes=["tiny_000"], out=tmp_path / "o", workers=1, agent_timeout=None)
    finally:
        for name in messages:
            GUARDS.unregister(name)
    with ResultStore(tmp_path / "o" / "results.sqlite") as store:
        crashed = [r for r in store.records() if r.status == "crashed"]
    assert res.crashed == 4 and res.done == 2          # the unguarded agent's episodes are unharmed
    for r in crashed:
        guard = r.agent.rpartition("+guard:")[2]
        assert messages[guard] in r.message


def test_attack_searches_behind_the_guard_too(tmp_path):
    from icrsumo.evaluation.attack import AttackOptions, run_attack

    doc = run_attack(AttackOptions(out=tmp_path / "a", agents=("instruction-follower",), guards=("plan",),
                                   routes=("tiny_000",), budget=2))
    row = "instruction-follower+guard:plan"
    assert set(doc["agents"]) == {"instruction-follower", row} and doc["agents"][row]["routes_searched"] == 1
    with ResultStore(tmp_path / "a" / "results.sqlite") as store:
        log = store.episode_log(row, "tiny_000", "attack", 1, 2026)
        stored = len(store.records())
    assert log.guard and log.agent == row
    # the report of an attack folder accounts for every stored episode, naming what its tables leave out
    from icrsumo.evaluation.run import report_only

    ep = report_only(tmp_path / "a", quiet=True).episodes
    assert ep.done + ep.crashed + ep.stored_not_in_report == stored
    assert "attack, transfer" in ep.stored_not_in_report_why
