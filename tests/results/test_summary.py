"""The typed summary (summary.json): JSON out byte for byte as summary.json holds it, JSON in
again; a malformed file is one InputError naming the file and the key; the old mapping view."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest
from records_example import FAMS, tiny, with_asks, with_blank  # tests/ is on pytest's pythonpath

from icrsumo.core.errors import InputError
from icrsumo.evaluation import EvalResult
from icrsumo.results.aggregate import summarize
from icrsumo.results.summary import DecisionStats, Summary

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "golden"
REAL = sorted(GOLDEN.glob("*/summary.json"))


@pytest.mark.parametrize("path", REAL, ids=[p.parent.name for p in REAL])
def test_a_real_summary_round_trips_byte_for_byte(path):
    text = path.read_text(encoding="utf-8")
    s = Summary.from_json(text, path)
    assert s.to_json() == text and Summary.read(path) == s
    assert s.scoring == "lb1" and s.digest.startswith("sha256:")
    agent, a = next(iter(s.agents.items()))
    doc = json.loads(text)["agents"][agent]
    fam = next(iter(a.families))
    assert a.baseline.ds == doc["baseline"]["DS"] and a.families[fam].d_ds == doc["families"][fam]["dDS"]
    assert a.families[fam].decisions.decisions == doc["families"][fam]["decisions"]


def _llm_summary() -> Summary:
    """A summary with every optional part: answers, decision statistics with the answers'
    confusion, episodes not in the report, a crash."""
    recs = [replace(r, model_calls=4, invalid_answers=1) for r in tiny()]
    s = summarize(recs, suite="tiny", seed=7, k=2, families=FAMS, n_boot=100, scoring="lb1", digest=None,
                  rescored_short=2, not_in_report=3, not_in_report_why="they are of other agents")
    stats = DecisionStats({"followed_route": 1, "followed_text": 0, "other": 0, "not_reached": 1}, 0.5,
                          {"left": {"left": 1}}, None, {"left": {"right": 2}})
    a = s.agents["A"]
    fams = {f: replace(b, decisions=replace(stats, compliance=0.25)) for f, b in a.families.items()}
    return replace(s, agents={**s.agents, "A": replace(a, baseline=replace(a.baseline, decisions=stats),
                                                           families=fams)})


def test_every_optional_part_round_trips_in_summary_json_order():
    s = _llm_summary()
    text = s.to_json()
    assert Summary.from_json(text) == s and Summary.from_json(text).to_json() == text
    doc = json.loads(text)
    base = doc["agents"]["A"]["baseline"]
    assert list(base)[-6:] == ["invalid_answers", "invalid_rate", "decisions", "adherence", "confusion",
                               "answers"]  # no compliance on the baseline
    fam = doc["agents"]["A"]["families"]["paraphrase"]
    assert list(fam)[-10:] == ["flips", "model_calls", "invalid_answers", "invalid_rate", "p_value",
                               "decisions", "adherence", "confusion", "compliance", "answers"]
    assert doc["episodes"] == {"done": 16, "crashed": 2, "rescored_short": 2, "stored_not_in_report": 3,
                               "stored_not_in_report_why": "they are of other agents"}
    assert list(doc)[-2:] == ["scoring", "digest"] and doc["digest"] is None
    assert s.has_answers and s.agents["B"].baseline.answers.invalid_rate == 0.25


def test_without_a_scoring_neither_scoring_nor_digest_is_written():
    s = summarize(tiny(), suite="tiny", seed=7, k=2, families=FAMS, n_boot=100)
    assert "scoring" not in s.to_dict() and "digest" not in s.to_dict()
    assert Summary.from_json(s.to_json()) == s


@pytest.mark.parametrize(("edit", "place", "problem"), [
    (lambda d: d["agents"]["A"]["families"]["paraphrase"].pop("dDS"), "agents.A.families.paraphrase",
     "missing key 'dDS'"),
    (lambda d: d["agents"]["B"]["baseline"].update(n="2"), "agents.B.baseline.n", "n must be"),
    (lambda d: d["agents"]["A"]["families"]["paraphrase"].update(dDS_ci95=[1.0]),
     "agents.A.families.paraphrase.dDS_ci95", "not [lo, hi]"),
    (lambda d: d.update(seed=None), "seed", "seed must be"),
    (lambda d: d["agents"]["A"].update(conditioning_gain={"DS": 1.0}), "agents.A.conditioning_gain",
     "missing key 'RC'"),
    (lambda d: d["agents"]["B"].update(conditioning_gain=[]), "agents.B.conditioning_gain", "must be"),
    (lambda d: d["agents"]["A"]["baseline"].update(asks=1), "agents.A.baseline",
     "missing key 'asks_answered'"),
    (lambda d: d["agents"]["A"]["baseline"].update(asks=-1, asks_answered=0), "agents.A.baseline.asks",
     "out of range"),
])
def test_a_malformed_summary_is_one_line_naming_the_file_and_the_key(tmp_path, edit, place, problem):
    doc = summarize(tiny(), suite="tiny", seed=7, k=2, families=FAMS, n_boot=100).to_dict()
    edit(doc)
    path = tmp_path / "summary.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(InputError) as err:
        Summary.read(path)
    line = err.value.line()
    assert line.startswith(f"{path}: {place}: ") and problem in line and "\n" not in line
    assert "icrsumo report" in line  # the fix


def test_the_conditioning_gain_round_trips_after_the_families():
    s = summarize(with_blank(), suite="g", seed=7, k=8, families=("misleading", "blank"), n_boot=100)
    text = s.to_json()
    back = Summary.from_json(text)
    assert back == s and back.to_json() == text and back.agents["A"].conditioning_gain.ds == 25.0
    assert list(json.loads(text)["agents"]["A"]) == ["baseline", "families", "conditioning_gain"]
    doc = s.to_dict()
    doc["agents"]["A"]["conditioning_gain"] = None  # null reads as no gain
    assert Summary.from_dict(doc).agents["A"].conditioning_gain is None


def test_the_ask_counts_round_trip_beside_the_answers():
    s = summarize(with_asks(), suite="tiny", seed=7, k=2, families=FAMS, n_boot=100)
    text = s.to_json()
    back = Summary.from_json(text)
    assert back == s and back.to_json() == text and back.has_asks
    assert back.agents["A"].families["paraphrase"].asking.ask_rate == 0.3333
    doc = json.loads(text)["agents"]["A"]
    asks = ["asks", "asks_answered", "ask_rate", "asks_per_episode", "answered_rate"]
    assert list(doc["baseline"])[-5:] == asks  # after the plain values (and a model's answers)
    assert list(doc["families"]["paraphrase"])[-6:] == [*asks, "p_value"]
    plain = summarize(tiny(), suite="tiny", seed=7, k=2, families=FAMS, n_boot=100)
    assert Summary.from_json(plain.to_json()) == plain and not plain.has_asks  # no asks: no keys, None


def test_the_old_mapping_view_still_reads_but_is_deprecated():
    s = summarize(tiny(), suite="tiny", seed=7, k=2, families=FAMS, n_boot=100)
    with pytest.deprecated_call():
        assert s["agents"]["A"]["baseline"]["DS"] == s.agents["A"].baseline.ds == 63.3333


def test_eval_result_keeps_the_mapping_and_adds_the_typed_summary(tmp_path):
    s = _llm_summary()
    run = EvalResult(stats=s, out=tmp_path, episodes=18, ran=0, done=16, crashed=2)
    assert run.summary == json.loads(s.to_json()) and run.stats is s and run.digest is None
    assert run.summary["agents"]["A"]["baseline"]["DS"] == run.stats.agents["A"].baseline.ds
