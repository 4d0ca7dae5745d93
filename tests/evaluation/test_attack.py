"""icrsumo attack: the rewrite space keeps the meaning, the search is deterministic and resumes
from the store, and the route-oracle (which never reads the text) is never broken."""

from __future__ import annotations

import json

import pytest

from icrsumo.app.cli.main import main
from icrsumo.core.types import Instruction, Intent
from icrsumo.evaluation.attack import AttackOptions, run_attack
from icrsumo.instructions.banks import load_banks
from icrsumo.instructions.intent import classify_intent
from icrsumo.instructions.rewrites import rewrite_pool
from icrsumo.instructions.store import read_instruction_sets
from icrsumo.results.store import ResultStore


def test_the_goal_space_keeps_the_intent_and_the_misleading_one_contradicts_it():
    banks = load_banks(None)
    for text, intent in [("Turn left at the traffic light.", Intent.LEFT),
                         ("In [x] meters, change to the right lane.", Intent.LANE_RIGHT),
                         ("Follow the road.", Intent.FOLLOW)]:
        ins = Instruction(1, 0.0, text, intent, "t", distance=50.0 if "[x]" in text else None)
        goal = rewrite_pool(ins, banks, 2026, "r1")
        assert len(goal) > 50 and text not in {t for t, _ in goal}
        assert len({t for t, _ in goal}) == len(goal)
        for t, tid in goal:
            assert classify_intent(t) == intent and ("[x]" in t) == ("[x]" in text), (t, tid)
        assert rewrite_pool(ins, banks, 2026, "r1") == goal  # seeded noise: the same pool
        more = rewrite_pool(ins, banks, 2026, "r1", misleading=True)[len(goal):]
        assert more and all(classify_intent(t) != intent for t, _ in more)
    assert rewrite_pool(Instruction(0, 0.0, "Stop.", Intent.STOP, "t"), banks, 1, "r") == ()


@pytest.mark.sumo
def test_attack_is_deterministic_resumes_and_spares_the_oracle(suite, tmp_path):
    def attack(out, budget):
        return run_attack(AttackOptions(out=out, suite=str(suite), agents=("route-oracle", "bev-token"),
                                        budget=budget, workers=1))

    first = attack(tmp_path / "a", 2)
    oracle = first["agents"]["route-oracle"]
    assert oracle["routes_searched"] == 1 and oracle["successes"] == 0 and oracle["worst_dDS"] == 0.0
    resumed = attack(tmp_path / "a", 3)  # one more query per agent and route; the first two replayed
    with ResultStore(tmp_path / "a" / "results.sqlite") as s:
        ks = sorted((r.agent, r.k) for r in s.records() if r.family == "attack")
    assert ks == [("bev-token", 1), ("bev-token", 2), ("bev-token", 3),
                  ("route-oracle", 1), ("route-oracle", 2), ("route-oracle", 3)]
    fresh = attack(tmp_path / "b", 3)
    assert json.dumps(resumed, sort_keys=True) == json.dumps(fresh, sort_keys=True)
    assert (tmp_path / "a" / "attack.md").read_text() == (tmp_path / "b" / "attack.md").read_text()
    token = fresh["agents"]["bev-token"]["routes"]["tiny_003"]
    if first["agents"]["bev-token"]["routes"]["tiny_003"]["first_success"] is not None:
        assert token["first_success"] == first["agents"]["bev-token"]["routes"]["tiny_003"]["first_success"]
    for path in (tmp_path / "b" / "attack" / "goal").rglob("tiny_003.json"):
        for s in read_instruction_sets(path)[1:]:
            for ins in s.instructions:
                if ins.template != "keep":
                    assert classify_intent(ins.rendered()) == ins.intent, ins.text
    assert set(fresh["transfer"]) == {"route-oracle", "bev-token"}


def test_bad_attack_options_are_one_line(tmp_path, capsys):
    code = main(["attack", "--budget", "0", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--budget: 0: out of range" in err[0]
    assert not (tmp_path / "o").exists()


def test_a_compare_folder_with_a_malformed_summary_is_refused_before_any_episode(tmp_path, capsys):
    grid = tmp_path / "grid"
    grid.mkdir()
    (grid / "results.sqlite").write_bytes(b"")
    (grid / "summary.json").write_text(json.dumps({"suite": "tiny", "seed": 1, "k": 1}), encoding="utf-8")
    code = main(["attack", "--compare", str(grid), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert f"{grid / 'summary.json'}: top level: missing key 'episodes'" in err[0]
    assert not (tmp_path / "o").exists()
