"""The delivery families (issue 45): timing, distance, correction and notice, built on the
bundled routes and checked against the routes' own geometry and networks."""

from __future__ import annotations

import bisect
import json
import re
from pathlib import Path

import pytest

from icrsumo.core.errors import InputError
from icrsumo.core.types import Intent
from icrsumo.core.vocab import DELIVERY_FAMILIES, FAMILIES
from icrsumo.instructions.banks import ORDINALS, baseline_catalogue, load_banks
from icrsumo.instructions.delivery import EARLY_BEFORE_M, FIX_ROOM_M, WRONG_M, _lower_first
from icrsumo.instructions.delivery_common import DeliveryParams, navigator_metres
from icrsumo.instructions.delivery_texts import (
    CORRECTION_PREFIXES,
    DISTANCE_HIGHWAY_EXIT,
    DISTANCE_ROUNDABOUT,
    DISTANCE_STRAIGHT,
    DISTANCE_TURN,
    NOTICE_TEXTS,
    ORDINAL_TURN,
)
from icrsumo.instructions.generate import GenerateOptions, generate
from icrsumo.instructions.intent import classify_intent
from icrsumo.instructions.notices import MIN_LEAD_M
from icrsumo.instructions.store import read_route_file, skipped_families
from icrsumo.world.networks import load_net
from icrsumo.world.scenario import find_scenarios, read_scenario

K = 4
PARAMS = DeliveryParams()


def _fill(text: str, **slots: str) -> str:
    for k, v in slots.items():
        text = text.replace("{" + k + "}", v)
    return text.replace("[x]", "120")


# ------------------------------------------------------------------------------ texts, no SUMO
def test_every_text_reads_as_what_it_names():
    for d in ("left", "right"):
        for _, t in DISTANCE_TURN:
            assert classify_intent(_fill(t, dir=d)) == Intent(d), t
        for _, t in ORDINAL_TURN:
            for o in ORDINALS:
                assert classify_intent(_fill(t, dir=d, ord=o)) == Intent(d), t
    for _, t in DISTANCE_STRAIGHT:
        assert classify_intent(_fill(t)) == Intent.STRAIGHT, t
    for _, t in DISTANCE_HIGHWAY_EXIT:
        assert classify_intent(_fill(t)) == Intent.RIGHT, t
    for n, o in enumerate(ORDINALS[:3]):
        for _, t in DISTANCE_ROUNDABOUT:
            assert classify_intent(_fill(t, exit=o)) == (Intent.RIGHT, Intent.STRAIGHT, Intent.LEFT)[n], t
    for texts in NOTICE_TEXTS.values():
        for _, t in texts:
            assert classify_intent(t) in (Intent.STOP, Intent.UNKNOWN), t


def test_a_correction_reads_as_the_baseline_text_it_opens():
    """Every opening phrase before every concrete baseline text that reads as its maneuver."""
    checked = 0
    for _, text, intent in baseline_catalogue(load_banks(None)):
        text = text.replace("[x]", "50")
        if classify_intent(text) != intent:
            continue
        for _, prefix in CORRECTION_PREFIXES:
            assert classify_intent(prefix + _lower_first(text)) == intent, (prefix, text)
            checked += 1
    assert checked > 2000


def test_distances_are_rounded_as_navigators_say_them():
    assert [navigator_metres(d) for d in (3, 24, 86, 96, 130, 212, 480, 760, 1240)] == \
        [10, 20, 90, 100, 150, 200, 500, 800, 1200]


@pytest.mark.parametrize("params, field", [
    (DeliveryParams(late_m=(20.0, 10.0)), "late_m"), (DeliveryParams(late_m=(5.0, 40.0)), "late_m"),
    (DeliveryParams(early_m=(0.0, 10.0)), "early_m"), (DeliveryParams(correction_m=5.0), "correction_m"),
    (DeliveryParams(notice_lead_m=(5.0, 20.0)), "notice_lead_m")])
def test_a_parameter_out_of_range_is_one_error_naming_it(params, field):
    with pytest.raises(InputError) as err:
        GenerateOptions(families=("timing",), delivery=params).check()
    assert err.value.field == "delivery" and err.value.place == field and "out of range" in str(err.value)


# ------------------------------------------------------------------------------ built on routes
@pytest.fixture(scope="module")
def delivered(converted, tmp_path_factory) -> dict[str, Path]:
    out = {}
    for split in ("tiny", "short", "long"):
        o = tmp_path_factory.mktemp(f"delivery_{split}")
        written, failures = generate(converted[split], o, GenerateOptions(families=DELIVERY_FAMILIES, k=K))
        assert failures == [] and written
        out[split] = o
    return out


def _routes(delivered, converted):
    """(scenario, its network, baseline, maneuvers, sets by (family, k)) of every route."""
    for split, folder in delivered.items():
        scenarios = {read_scenario(d).route_id: read_scenario(d) for d in find_scenarios(converted[split])}
        for f in sorted(folder.glob("*.json")):
            if f.name == "index.json":
                continue
            sets, maneuvers = read_route_file(f)
            sc = scenarios[sets[0].route_id]
            yield sc, load_net(sc.net), sets[0], maneuvers, {(s.family, s.k): s for s in sets[1:]}


def _changed(s, template: str):
    return [i for i in s.instructions if re.fullmatch(template, i.template)]


def test_timing_delivers_the_baseline_text_late_or_early(delivered, converted):
    seen = {"late": 0, "early": 0}
    for sc, _, base, _, sets in _routes(delivered, converted):
        for k in range(K):
            s = sets.get(("timing", k))
            if s is None:
                continue
            late = _changed(s, "late")
            assert len({round(i.maneuver_pos - i.trigger, 1) for i in late}) <= 1  # one distance a variant
            for i in s.instructions:
                if i.template == "keep":
                    continue
                seen[i.template] += 1
                assert i.text == i.source and classify_intent(i.rendered()) == i.intent
                assert i.text in [b.text for b in base.instructions if b.maneuver_pos == i.maneuver_pos]
                # held until the junction: nothing comes between it and the junction
                after = [j.trigger for j in s.instructions if j.trigger > i.trigger]
                assert not after or after[0] > i.maneuver_pos
                if i.template == "late":
                    assert PARAMS.late_m[0] - 0.06 <= i.maneuver_pos - i.trigger <= PARAMS.late_m[1] + 0.06
                else:
                    assert k % 2 == 1
                    before = [j for j in sc.route.junctions if j.pos < i.maneuver_pos - 0.5]
                    assert not before[-1].choice and i.trigger <= before[-1].pos - EARLY_BEFORE_M
    assert seen["late"] > 50 and seen["early"] > 0, seen


def _offers(net, j, intent: Intent) -> bool:
    dirs = {c.direction for (a, _), conns in net.connections.items() if a == j.from_edge for c in conns}
    return j.choice and j.from_edge not in net.roundabout_edges and bool(
        dirs & ({"l", "L"} if intent == Intent.LEFT else {"r", "R"}))


def test_distances_and_ordinals_are_true_to_the_route(delivered, converted):
    ordinals = []
    for sc, net, _, _, sets in _routes(delivered, converted):
        for (fam, _), s in sets.items():
            if fam != "distance":
                continue
            for i in _changed(s, "d.*|o.*"):
                assert classify_intent(i.rendered()) == i.intent, i.rendered()
                assert i.trigger < i.maneuver_pos
                if i.template.startswith("d"):
                    assert i.distance == navigator_metres(i.maneuver_pos - i.trigger)
                    assert str(int(i.distance)) in i.rendered()
                    continue
                # the junctions from its trigger to the turn that offer it, the turn's own included
                n = sum(1 for j in sc.route.junctions if i.trigger <= j.pos <= i.maneuver_pos + 0.01
                        and (abs(j.pos - i.maneuver_pos) < 0.01 or _offers(net, j, i.intent)))
                word = ORDINALS[n - 1]
                assert re.search(rf"\b{word}\b", i.text) and i.distance is None, (i.text, n)
                ordinals.append(word)
    assert "first" in ordinals and "second" in ordinals


def test_a_correction_comes_before_the_junction_and_reads_as_the_route(delivered, converted):
    contradicts = {Intent.LEFT: {Intent.RIGHT}, Intent.RIGHT: {Intent.LEFT},
                   Intent.STRAIGHT: {Intent.LEFT, Intent.RIGHT}, Intent.FOLLOW: {Intent.LEFT, Intent.RIGHT}}
    n = 0
    for _, _, base, _, sets in _routes(delivered, converted):
        for (fam, _), s in sets.items():
            if fam != "correction":
                continue
            instrs = s.instructions
            assert len({i.id for i in instrs}) == len(instrs)
            kept = [(i.id, i.trigger, i.text) for i in instrs if i.template == "keep"]
            assert set(kept) <= {(b.id, b.trigger, b.text) for b in base.instructions}
            triggers = [i.trigger for i in instrs]
            for w, fix in zip(instrs, instrs[1:]):
                if not w.template.startswith("M."):
                    continue
                n += 1
                assert fix.template.startswith("fix:") and fix.maneuver_pos == w.maneuver_pos
                assert classify_intent(w.rendered()) in contradicts[w.intent]
                assert classify_intent(fix.rendered()) == fix.intent == w.intent
                assert w.trigger + WRONG_M - 0.01 <= fix.trigger <= fix.maneuver_pos - FIX_ROOM_M + 0.01
                # at the junction the ego reads the correction
                assert instrs[bisect.bisect_right(triggers, fix.maneuver_pos) - 1] is fix
    assert n > 50


def test_notices_go_where_the_network_has_the_thing(delivered, converted):
    kinds = {"notice_traffic_light": lambda t, j, net: t.startswith("traffic_light"),
             "notice_stop_sign": lambda t, j, net: t in ("priority_stop", "allway_stop"),
             "notice_pedestrians": lambda t, j, net: j.junction in net.crossing_nodes,
             "notice_merging": lambda t, j, net: True}
    added = 0
    for sc, net, base, _, sets in _routes(delivered, converted):
        for (fam, _), s in sets.items():
            if fam != "notice":
                continue
            assert [(i.id, i.trigger, i.text) for i in s.instructions] == \
                [(i.id, i.trigger, i.text) for i in base.instructions]
            assert set(base.notices) <= set(s.notices)
            mine = [n for n in s.notices if n not in base.notices]
            assert mine and all(classify_intent(n.text) in (Intent.STOP, Intent.UNKNOWN) for n in mine)
            assert [n.trigger for n in s.notices] == sorted(n.trigger for n in s.notices)
            for n in mine:  # never over another: the baseline's are shown as in the baseline
                assert not any(o.trigger < n.end and n.trigger < o.end for o in s.notices if o is not n)
                if n.type == "notice_caution":
                    continue
                added += 1
                assert any(kinds[n.type](net.node_type.get(j.junction, ""), j, net)
                           and n.trigger + MIN_LEAD_M - 0.01 <= j.pos < n.end for j in sc.route.junctions)
    assert added > 20


def test_same_seed_same_bytes_and_a_grown_k_keeps_the_variants(converted, tmp_path):
    tiny = converted["tiny"]

    def run(name: str, **kw) -> dict[str, bytes]:
        generate(tiny, tmp_path / name, GenerateOptions(**kw))
        return {f.name: f.read_bytes() for f in sorted((tmp_path / name).glob("*.json"))}

    a = run("a", families=FAMILIES + DELIVERY_FAMILIES, k=3)
    assert run("b", families=FAMILIES + DELIVERY_FAMILIES, k=3) == a
    assert run("c", families=FAMILIES + DELIVERY_FAMILIES, k=3, seed=7) != a
    four = run("d", families=FAMILIES, k=3)
    grown = run("e", families=DELIVERY_FAMILIES, k=5, grown_from=(3,))
    for name, text in a.items():
        if name == "index.json":
            continue
        doc = json.loads(text)
        assert "skipped" not in json.loads(four[name]) and "delivery" not in json.loads(four[name])
        # the four families' draws are those made without the delivery families
        wording = [s for s in doc["sets"] if s["family"] not in DELIVERY_FAMILIES]
        assert wording == json.loads(four[name])["sets"]
        big = {(s["family"], s["k"]): s for s in json.loads(grown[name])["sets"]}
        for s in doc["sets"]:
            if s["family"] in DELIVERY_FAMILIES:
                assert big[(s["family"], s["k"])] == s


def test_a_family_that_cannot_be_built_is_named_skipped_and_counted(converted, tmp_path, capsys):
    out = tmp_path / "g"
    written, failures = generate(converted["tiny"], out, GenerateOptions(families=("notice", "timing"), k=2))
    assert failures == [] and len(written) == 16
    err = capsys.readouterr().err.splitlines()
    skipped = skipped_families(out)
    assert skipped and len(err) == sum(len(f) for f in skipped.values())
    index = json.loads((out / "index.json").read_text())
    assert len(index["skipped"]) == len(err)
    for row, line in zip(index["skipped"], err):
        rid, fam = row["route_id"], row["family"]
        assert line.startswith(f"icrsumo: note: route {rid}: family {fam} cannot be built: ")
        assert row["why"] in line and "skipped" in line
        sets, _ = read_route_file(out / f"{rid}.json")
        assert fam not in {s.family for s in sets}
        assert json.loads((out / f"{rid}.json").read_text())["skipped"][fam] == row["why"]
    assert skipped["tiny_000"] == {"notice": index["skipped"][0]["why"]}


def test_a_set_keeps_its_own_notices_and_ids_stay_unique(delivered, tmp_path):
    path = next(p for p in sorted(delivered["tiny"].glob("tiny_*.json"))
                if any(s["family"] == "notice" for s in json.loads(p.read_text())["sets"]))
    sets, _ = read_route_file(path)
    notice = next(s for s in sets if s.family == "notice")
    assert len(notice.notices) > len(sets[0].notices)
    assert all(s.notices == sets[0].notices for s in sets if s.family != "notice")
    doc = json.loads(path.read_text())
    doc["sets"][0]["instructions"][-1]["id"] = doc["sets"][0]["instructions"][0]["id"]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"sets\[0\]\.instructions\[\d+\]\.id: a second instruction with id"):
        read_route_file(bad)


def test_generate_s_closing_line_counts_the_skipped_pairs(converted, tmp_path):
    import subprocess
    import sys

    out = tmp_path / "g"
    p = subprocess.run([sys.executable, "-m", "icrsumo", "generate", str(converted["tiny"]),
                        "--out", str(out), "--families", "notice,timing", "--k", "2"],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    n = sum(len(f) for f in skipped_families(out).values())
    assert n > 0
    assert f"16 routes x (1 + 2 x 2) sequences, {n} route-family pairs skipped" in p.stderr.splitlines()[-1]
