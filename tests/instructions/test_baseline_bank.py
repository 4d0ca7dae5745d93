"""--baseline-bank: LangAuto's own baseline wording from an LMDrive-layout instruction
dictionary (tests/data/langauto_style_bank.json holds our own phrasings in that layout; no
LMDrive sentence is shipped)."""

from __future__ import annotations

import hashlib
import json
import re
import shutil
from pathlib import Path

import pytest

from icrsumo.app.cli.main import main
from icrsumo.core.errors import InputError
from icrsumo.core.types import Intent, Maneuver
from icrsumo.instructions.banks import BASELINE_TYPES, ORDINALS, fill, load_banks
from icrsumo.instructions.baseline import build_baseline
from icrsumo.instructions.baseline_bank import (
    LANGAUTO_IDS,
    LANGAUTO_MEANINGS,
    langauto_id,
    load_baseline_bank,
)

DATA = Path(__file__).parents[1] / "data"
BANK = DATA / "langauto_style_bank.json"
L, R = Intent.LEFT, Intent.RIGHT


def _bank_json() -> dict:
    return json.loads(BANK.read_text(encoding="utf-8"))


def _slots(itype: str, intent: Intent, exit_ordinal: str = "") -> dict[str, str]:
    """The slots the builder fills for an instruction of ``itype`` with ``intent``."""
    rule = BASELINE_TYPES[itype]
    if rule == "{dir}":
        return {"dir": intent.value}
    if rule == "lane_{side}":
        return {"side": intent.value.removeprefix("lane_")}
    if rule == "{exit}":
        return {"exit": exit_ordinal}
    return {}


def _check_texts(instructions, notices, bank: dict) -> tuple[int, int]:
    """Every text comes from the user's bank where it maps the type (and has the id), else
    from icrsumo's bank; (texts from the user's bank, texts from icrsumo's)."""
    ours = load_banks().baseline
    user = icr = 0
    items = [(i.type, i.text, _slots(i.type, i.intent, _exit(i.text))) for i in instructions]
    items += [(n.type, n.text, {}) for n in notices]
    for itype, text, slots in items:
        lid = langauto_id(itype, slots)
        if lid is not None and lid in bank:
            assert text in bank[lid], (itype, text)
            user += 1
        else:
            assert text in {fill(p, **slots) for p in ours[itype]}, (itype, text)
            icr += 1
    return user, icr


def _exit(text: str) -> str:
    return next((o for o in ORDINALS if o in text), "")


# --- the mapping table ----------------------------------------------------------------------


def test_mapping_table_is_consistent():
    assert set(LANGAUTO_MEANINGS) == {str(i) for i in range(65)}
    assert set(LANGAUTO_IDS) <= set(BASELINE_TYPES)
    kinds: dict[str, set[bool]] = {}
    for itype, entry in LANGAUTO_IDS.items():
        values = entry if isinstance(entry, dict) else {"": entry}
        rule = BASELINE_TYPES[itype]
        if rule in ("{dir}", "lane_{side}"):
            assert set(values) == {"left", "right"}, itype
        elif rule == "{exit}":
            assert set(values) <= set(ORDINALS), itype
        else:
            assert set(values) == {""}, itype
        for lid in values.values():
            assert lid in LANGAUTO_MEANINGS
            # a distance type is shown with [x], and so is the LangAuto type it maps to
            assert ("[x]" in LANGAUTO_MEANINGS[lid]) == itype.endswith("_distance"), (itype, lid)
            kinds.setdefault(lid, set()).add(itype.endswith("_distance"))
    assert all(len(v) == 1 for v in kinds.values())
    # types LangAuto has no counterpart for keep icrsumo's phrasing
    for itype in ("highway_enter", "notice_traffic_light", "notice_stop_sign"):
        assert langauto_id(itype) is None
    assert langauto_id("roundabout_exit", {"exit": "fourth"}) is None
    assert langauto_id("turn_traffic_light", {"dir": "right"}) == "11"


def test_fixture_bank_loads():
    bank = load_baseline_bank(BANK)
    data = _bank_json()
    assert bank.sha256 == hashlib.sha256(BANK.read_bytes()).hexdigest()
    assert bank.set_aside == ()
    assert bank.phrasings_for("turn_intersection", {"dir": "left"}) == tuple(data["4"])
    assert bank.phrasings_for("turn_stop_sign", {"dir": "right"}) == tuple(data["5"])
    assert bank.phrasings_for("follow_distance") == tuple(data["40"])
    assert bank.phrasings_for("straight_traffic_light") is None  # id 12 is not in the file
    assert bank.phrasings_for("highway_enter") is None  # no LangAuto counterpart
    assert bank.phrasings_for("notice_traffic_light") is None
    assert bank.phrasings_for("roundabout_exit", {"exit": "second"}) == tuple(data["23"])
    assert bank.phrasings_for("roundabout_exit", {"exit": "fourth"}) is None


def test_phrasings_the_classifier_misreads_are_set_aside(tmp_path):
    f = tmp_path / "bank.json"
    f.write_text(json.dumps({"4": ["Turn left at the next intersection.", "Change to the left lane."],
                             "5": ["Change to the right lane."]}))
    bank = load_baseline_bank(f)
    left = bank.phrasings_for("turn_intersection", {"dir": "left"})
    assert left == ("Turn left at the next intersection.",)
    assert bank.phrasings_for("turn_intersection", {"dir": "right"}) is None  # icrsumo's wording stays
    assert [(s.id, s.index, s.classified, s.wanted) for s in bank.set_aside] == [
        ("4", 1, Intent.LANE_LEFT, L), ("5", 0, Intent.LANE_RIGHT, R)]
    assert bank.describe()["set_aside"][0].startswith('"4"[1]: ')


# --- the baseline sequence --------------------------------------------------------------------


def _maneuvers() -> list[Maneuver]:
    """Every junction kind and lane changes, spaced for far and near announcements."""
    return [
        Maneuver("turn_left", 200.0, L, "traffic_light", "j1"),
        Maneuver("straight", 400.0, Intent.STRAIGHT, "crossroad", "j2"),
        Maneuver("lane_change_right", 450.0, Intent.LANE_RIGHT),
        Maneuver("turn_right", 600.0, R, "t_junction", "j3"),
        Maneuver("roundabout", 800.0, Intent.STRAIGHT, "roundabout", "j4", exit=2),
        Maneuver("turn_left", 1000.0, L, "stop_sign", "j5"),
        Maneuver("straight", 1200.0, Intent.STRAIGHT, "traffic_light", "j6"),
        Maneuver("roundabout", 1400.0, L, "roundabout", "j7", exit=4),
        Maneuver("highway_enter", 1600.0, Intent.FOLLOW, "highway_entry", "j8"),
        Maneuver("highway_exit", 2000.0, R, "highway_exit", "j9"),
    ]


def test_build_baseline_draws_mapped_types_from_the_bank():
    banks, bank = load_banks(), load_baseline_bank(BANK)
    ms = _maneuvers()
    crossings = frozenset({"j1", "j5", "j6"})
    with_bank = build_baseline("r", 2300.0, ms, banks, 11, ((1600.0, 2000.0),), crossings, bank)
    user, icr = _check_texts(with_bank.instructions, with_bank.notices, _bank_json())
    assert user >= 8 and icr >= 4  # both sources used
    # the same seed gives the same text; only the wording differs from icrsumo's own sequence
    again = build_baseline("r", 2300.0, ms, banks, 11, ((1600.0, 2000.0),), crossings, bank)
    assert again == with_bank
    plain = build_baseline("r", 2300.0, ms, banks, 11, ((1600.0, 2000.0),), crossings)
    assert [(i.id, i.trigger, i.type, i.intent, i.distance) for i in plain.instructions] == \
        [(i.id, i.trigger, i.type, i.intent, i.distance) for i in with_bank.instructions]
    assert [i.text for i in plain.instructions] != [i.text for i in with_bank.instructions]
    by_type = {i.type: i.text for i in with_bank.instructions}
    assert by_type["straight_traffic_light"] in {p for p in banks.baseline["straight_traffic_light"]}
    assert by_type["highway_enter"] in banks.baseline["highway_enter"]
    fourth = [i.text for i in with_bank.instructions if i.type == "roundabout_exit" and "fourth" in i.text]
    assert fourth  # a fourth exit has no LangAuto id: icrsumo's phrasing


def test_distance_slot_is_filled_when_shown():
    bank = load_baseline_bank(BANK)
    seq = build_baseline("r", 400.0, [Maneuver("turn_right", 300.0, R, "junction", "j")], load_banks(), 3,
                         baseline_bank=bank)
    far = next(i for i in seq.instructions if i.type == "turn_distance")
    assert far.text in _bank_json()["3"] and "[x]" in far.text
    assert far.rendered() == far.text.replace("[x]", "80") and "[x]" not in far.rendered()


# --- bad input: one kind per case -------------------------------------------------------------

BAD = {
    "not_json": (b'{"0": ["Turn left."]', "malformed JSON"),
    "trailing_garbage": (b'{"0": ["Turn left."]} and more', "malformed JSON"),
    "nan_constant": (b'{"0": NaN}', "malformed JSON"),
    "duplicate_key": (b'{"0": ["Turn left."], "0": ["Go left."]}', "duplicate key '0'"),
    "too_deep": (b"[" * 200000, "malformed JSON"),
    "not_an_object": (b'["Turn left."]', "must be a JSON object, not list"),
    "empty_object": (b"{}", "holds no instruction types"),
    "key_not_integer": (b'{"left": ["Turn left."]}', "key 'left': not a LangAuto instruction-type id"),
    "key_out_of_range": (b'{"65": ["Turn left."]}', "key '65': not a LangAuto"),
    "key_leading_zero": (b'{"04": ["Turn left."]}', "key '04': not a LangAuto"),
    "key_negative": (b'{"-1": ["Turn left."]}', "key '-1': not a LangAuto"),
    "value_not_a_list": (b'{"0": "Turn left."}', 'must be a non-empty list'),
    "value_empty_list": (b'{"0": []}', 'must be a non-empty list'),
    "phrasing_not_a_string": (b'{"0": [3]}', '"0"[0]: phrasing must be a non-empty string'),
    "phrasing_blank": (b'{"0": ["Turn left.", "  "]}', '"0"[1]: phrasing must be a non-empty string'),
    "phrasing_too_long": (('{"0": ["' + "left " * 80 + '"]}').encode(), "longer than 300"),
    "placeholder_unknown": (b'{"2": ["In [z] meters, turn left."]}', "unknown placeholder [z]"),
    "placeholder_upper_case": (b'{"2": ["In [X] meters, turn left."]}', "unknown placeholder [X]"),
    "placeholder_braces": (b'{"0": ["Turn {dir} here."]}', "unknown placeholder {dir}"),
    "bracket_unbalanced": (b'{"2": ["In [x meters, turn left."]}', "unbalanced bracket"),
    "slot_y_for_mapped_type": (b'{"2": ["In [x] meters, turn left, [y] over."]}', "uses [y]"),
    "slot_x_for_type_without_distance": (b'{"0": ["Turn left in [x] meters."]}', "uses [x]"),
    "slot_x_missing_for_distance_type": (b'{"40": ["Follow this road."]}', "lacks [x]"),
    "utf16_with_bom": ('{"0": ["Turn left."]}'.encode("utf-16"), "UTF-16"),
    "utf16_without_bom": ('{"0": ["Turn left."]}'.encode("utf-16-le"), "UTF-16"),
    "latin1": ('{"0": ["Turn left at the café."]}'.encode("latin-1"), "not UTF-8 (byte 0xe9)"),
}


@pytest.mark.parametrize("kind", sorted(BAD) + ["missing_file", "a_folder"])
def test_bad_bank_is_one_line_input_error(kind, tmp_path, capsys):
    f = tmp_path / "instruction_dict.json"
    if kind == "a_folder":
        f.mkdir()
        expect = "is not a file"
    elif kind == "missing_file":
        expect = "baseline bank not found"
    else:
        content, expect = BAD[kind]
        f.write_bytes(content)
    with pytest.raises(InputError) as err:
        load_baseline_bank(f)
    line = str(err.value)
    assert expect in line and str(f) in line and "\n" not in line and "(fix: " in line
    # the commands: exit status 2, one line on stderr, no traceback, nothing written
    out = tmp_path / "out"
    assert main(["generate", str(tmp_path), "--out", str(out), "--baseline-bank", str(f)]) == 2
    assert main(["evaluate", "--out", str(out), "--baseline-bank", str(f), "--agent", "route-oracle",
                 "--quiet"]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 2 and all(x.startswith("icrsumo: error: ") and expect in x for x in lines)
    assert "Traceback" not in captured.err and not out.exists()


def test_bank_problems_name_the_place(tmp_path):
    data = _bank_json()
    data["38"] = ["Stick with this road.", "Stay on this road for [x] meters."]
    f = tmp_path / "b.json"
    f.write_text(json.dumps(data))
    with pytest.raises(InputError, match=re.escape('b.json: "38"[1]: uses [x]')):
        load_baseline_bank(f)


# --- generate -----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny_none(tmp_path_factory) -> Path:
    """The tiny split converted without background traffic (the instructions do not depend on it)."""
    from icrsumo.core.resources import bundled_suites
    from icrsumo.world.convert import ConvertOptions, convert_routes

    out = tmp_path_factory.mktemp("tiny_none")
    rep = convert_routes(bundled_suites()["tiny"], out, ConvertOptions(traffic="none", workers=1))
    assert rep.failures == []
    return out


def _tree(root: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(root.glob("*.json"))}


@pytest.mark.sumo
def test_generate_uses_the_bank(tiny_none, tmp_path, capsys):
    from icrsumo.instructions.store import read_instruction_sets

    out = tmp_path / "a"
    assert main(["generate", str(tiny_none), "--out", str(out), "--k", "2",
                 "--baseline-bank", str(BANK)]) == 0
    assert "set aside" not in capsys.readouterr().err
    index = json.loads((out / "index.json").read_text())
    sha = hashlib.sha256(BANK.read_bytes()).hexdigest()
    assert index["failures"] == [] and len(index["routes"]) == 16
    assert index["baseline_bank"]["sha256"] == sha and index["baseline_bank"]["set_aside"] == []
    user = icr = 0
    for entry in index["routes"]:
        doc = json.loads((out / entry["file"]).read_text())
        assert doc["baseline_bank_sha256"] == sha
        sets = read_instruction_sets(out / entry["file"])
        assert len(sets) == 1 + 4 * 2
        u, i = _check_texts(sets[0].instructions, sets[0].notices, _bank_json())
        user, icr = user + u, icr + i
        for s in sets[1:]:  # the variants are made from the LangAuto-worded baseline
            assert [x.source for x in s.instructions] == [x.text for x in sets[0].instructions]
    assert user > 20 and icr > 5


@pytest.mark.sumo
def test_generate_with_the_bank_is_deterministic(tiny_none, tmp_path):
    args = ["generate", str(tiny_none), "--k", "1", "--families", "noise,paraphrase"]
    assert main([*args, "--out", str(tmp_path / "a"), "--baseline-bank", str(BANK), "--workers", "1"]) == 0
    copy = tmp_path / "elsewhere.json"
    shutil.copy(BANK, copy)
    assert main([*args, "--out", str(tmp_path / "b"), "--baseline-bank", str(copy), "--workers", "2"]) == 0
    a, b = _tree(tmp_path / "a"), _tree(tmp_path / "b")
    assert a.pop("index.json") != b.pop("index.json")  # it names the file
    assert a == b  # same bytes, same seed: same text
    assert main([*args, "--out", str(tmp_path / "c")]) == 0
    plain = _tree(tmp_path / "c")
    plain.pop("index.json")
    assert plain != a and not any(b"baseline_bank" in v for v in plain.values())
