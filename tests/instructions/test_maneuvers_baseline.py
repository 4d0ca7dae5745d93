"""Maneuvers from route geometry and the baseline sequences built from them."""

from __future__ import annotations

from collections import Counter

from icrsumo.instructions.banks import load_banks
from icrsumo.instructions.baseline import build_baseline
from icrsumo.instructions.intent import classify_intent
from icrsumo.instructions.maneuvers import extract_maneuvers, roundabout_intent
from icrsumo.instructions.store import read_instruction_sets
from icrsumo.networks import load_net
from icrsumo.scenario import find_scenarios, read_scenario
from icrsumo.types import Intent


def _all(converted):
    for split, d in converted.items():
        for sd in find_scenarios(d):
            sc = read_scenario(sd)
            yield split, sc, extract_maneuvers(sc, load_net(sc.net))


def test_maneuvers_cover_junction_kinds_and_lane_changes(converted):
    kinds, junctions = Counter(), Counter()
    for _, sc, ms in _all(converted):
        assert [m.pos for m in ms] == sorted(m.pos for m in ms)
        assert all(0 <= m.pos <= sc.length for m in ms)
        choice = sum(1 for j in sc.manifest["junctions"] if j["choice"])
        assert sum(1 for m in ms if not m.kind.startswith("lane")) >= min(1, choice)
        kinds.update(m.kind for m in ms)
        junctions.update(m.junction for m in ms)
    for k in ("turn_left", "turn_right", "straight", "roundabout", "lane_change_left",
              "lane_change_right"):
        assert kinds[k] > 0, kinds
    for j in ("traffic_light", "stop_sign", "t_junction", "crossroad", "roundabout"):
        assert junctions[j] > 0, junctions


def test_roundabout_exit_numbers(converted):
    seen = set()
    for _, _sc, ms in _all(converted):
        for m in ms:
            if m.kind == "roundabout":
                assert m.exit >= 1 and m.intent == roundabout_intent(m.exit)
                seen.add(m.exit)
    assert len(seen) >= 2
    assert roundabout_intent(1) == Intent.RIGHT and roundabout_intent(2) == Intent.STRAIGHT
    assert roundabout_intent(3) == Intent.LEFT


def test_baseline_sequences(converted, generated):
    counts = {}
    for split, d in generated.items():
        n = []
        for f in sorted(d.glob("*.json")):
            if f.name == "index.json":
                continue
            base = read_instruction_sets(f)[0]
            ins = base.instructions
            assert base.family == "baseline" and [i.id for i in ins] == list(range(len(ins)))
            assert all(b.trigger > a.trigger for a, b in zip(ins, ins[1:]))
            assert ins[0].trigger == 0.0
            for i in ins:
                assert ("[x]" in i.text) == (i.distance is not None)
                assert "{" not in i.text
                assert classify_intent(i.text) == i.intent, i.text
                assert "[x]" not in i.rendered()
            n.append(len(ins))
        counts[split] = sum(n) / len(n)
    assert 2.5 <= counts["tiny"] <= 6.5
    assert counts["long"] >= 9


def test_baseline_is_deterministic_per_route_seed(converted):
    banks = load_banks()
    _, sc, ms = next(_all(converted))
    a = build_baseline(sc.route_id, sc.length, ms, banks, sc.seed)
    b = build_baseline(sc.route_id, sc.length, ms, banks, sc.seed)
    c = build_baseline(sc.route_id, sc.length, ms, banks, sc.seed + 1)
    assert a == b
    assert [i.trigger for i in a.instructions] == [i.trigger for i in c.instructions]
