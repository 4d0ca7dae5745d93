"""Hostile and damaged input files: every problem is one InputError line naming the file (and
the place), never a traceback; nothing is written into an output folder before the inputs pass.

One test per kind of input file, its examples parametrized: XML the package hands to a parser
(route files, networks, OpenDRIVE, a scenario's SUMO files), waypoint numbers, template banks,
instruction files, scenario manifests and index.json, episode logs, the --baseline-bank file.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from icrsumo.app.cli.main import main
from icrsumo.core.errors import InputError
from icrsumo.core.resources import bundled_towns, data_dir

DATA = Path(__file__).parent / "data"
SMALL_NET = data_dir("networks") / "icr_rural.net.xml"
COMMENT_20K = "<!--" + "x" * 20_000 + "-->\n"
BAN = "holds a forbidden XML construct: <!DOCTYPE"
DTD = '<!DOCTYPE net [<!ENTITY e SYSTEM "file:///etc/passwd">]>\n'


def _one_line(err: InputError, path: Path | str) -> str:
    text = str(err)
    assert "\n" not in text and "Traceback" not in text
    assert str(path) in text or Path(path).name in text, text
    assert len(text) < 400, text
    return text


def _after_decl(text: str, insert: str) -> str:
    """``insert`` placed right after the XML declaration of ``text``."""
    i = text.index("?>") + 2 if text.startswith("<?xml") else 0
    return text[:i] + "\n" + insert + text[i:]


# ------------------------------------------------------------------ XML the package reads
def _xml_cases() -> dict[str, bytes]:
    net = SMALL_NET.read_text(encoding="utf-8")
    big_tail = net.encode() + b" " * (1 << 20) + b"<!ENTITY x 'y'>"  # past the first 1 MiB block
    cases = {
        "doctype after a 20 KB comment": _after_decl(net, COMMENT_20K + DTD).encode(),
        "entity after 1 MiB": big_tail,
        "lower-case doctype": _after_decl(net, COMMENT_20K + "<!doctype net>\n").encode(),
        "UTF-16 with BOM": _after_decl(net, DTD).encode("utf-16"),
        "UTF-16 without BOM": _after_decl(net, DTD).encode("utf-16-le"),
        "UTF-7 declared": net.replace('encoding="UTF-8"', 'encoding="UTF-7"', 1).encode(),
        "EBCDIC": net.encode("cp500"),
        "empty": b"",
        "not XML": b"root:x:0:0:root:/root:/bin/bash\n",
    }
    for shift in (-9, -5, -1, 0, 3):  # "<!DOCTYPE" straddling the 1 MiB block boundary
        pad = (1 << 20) - len("<net>") + shift
        cases[f"doctype at block boundary {shift:+d}"] = b"<net>" + b" " * pad + b"<!DOCTYPE x><x/>"
    return cases


_XML = _xml_cases()


@pytest.mark.parametrize("case", list(_XML))
def test_unsafe_or_foreign_xml_is_one_line(tmp_path, case):
    from icrsumo.world.networks import load_net
    from icrsumo.world.routes import check_xml_file, read_routes

    p = tmp_path / "evil.net.xml"
    p.write_bytes(_XML[case])
    for reader in (check_xml_file, load_net, read_routes):
        with pytest.raises(InputError) as err:
            reader(p)
        _one_line(err.value, p)
    if "doctype" in case.lower() or "entity" in case:
        assert "DTDs and entities are not read" in str(err.value)


def test_missing_folder_and_unreadable_xml(tmp_path):
    from icrsumo.world.routes import check_xml_file

    for p in (tmp_path / "missing.net.xml", tmp_path):
        with pytest.raises(InputError) as err:
            check_xml_file(p, "network file")
        _one_line(err.value, p)


def test_every_bundled_net_passes_the_check():
    from icrsumo.world.routes import check_xml_file

    towns = bundled_towns()
    assert towns
    for path in towns.values():
        check_xml_file(path, "network file")


def _routes_file(tmp_path: Path, town: str = "t") -> Path:
    p = tmp_path / "r.xml"
    p.write_text(f'<routes><route id="a" town="{town}"><waypoint x="1" y="2"/><waypoint x="3" y="4"/>'
                 '</route></routes>', encoding="utf-8")
    return p


def _evil_net(tmp_path: Path, name: str = "evil.net.xml") -> Path:
    p = tmp_path / name
    p.write_text(_after_decl(SMALL_NET.read_text(encoding="utf-8"), COMMENT_20K + DTD), encoding="utf-8")
    return p


_EMPTY_NET = ('<net version="1.20"><location netOffset="0,0" convBoundary="0,0,1,1" origBoundary="0,0,1,1" '
              'projParameter="!"/></net>')


@pytest.mark.parametrize(("make", "expect"), [
    (lambda d: _evil_net(d), f"line 3: network file {BAN}"),
    (lambda d: _write(d / "empty.net.xml", _EMPTY_NET), "has no lanes that passenger cars may use"),
    (lambda d: _write(d / "routes.net.xml", "<routes/>"), "not a readable SUMO network"),
    (lambda d: _write(d / "inf.net.xml", SMALL_NET.read_text(encoding="utf-8").replace(
        'netOffset="', 'netOffset="1e400,', 1)), "<location netOffset>: offset"),
])
def test_convert_with_bad_net_writes_nothing(tmp_path, capsys, make, expect):
    net = make(tmp_path)
    out = tmp_path / "out"
    code = main(["convert-routes", str(_routes_file(tmp_path)), "--out", str(out), "--net", str(net),
                 "--traffic", "none"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith(f"icrsumo: error: {net}: ") and expect in err[0], err
    assert not out.exists()


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def test_convert_with_hostile_net_dir_town_copies_no_net(tmp_path, capsys):
    nets = tmp_path / "nets"
    nets.mkdir()
    _evil_net(nets, "Evil.net.xml")
    out = tmp_path / "out"
    code = main(["convert-routes", str(_routes_file(tmp_path, "Evil")), "--out", str(out), "--net-dir",
                 str(nets), "--traffic", "none"])
    err = capsys.readouterr().err
    assert code == 2 and f"Evil.net.xml: line 3: network file {BAN}" in err
    assert not out.exists()  # no route converted: nothing written, no net copied


def test_convert_with_hostile_xodr_or_route_file_writes_nothing(tmp_path, capsys):
    xodr = tmp_path / "evil.xodr"
    xodr.write_text(_after_decl((DATA / "carla_mini.xodr").read_text(encoding="utf-8"),
                                COMMENT_20K + DTD.replace("net", "OpenDRIVE")), encoding="utf-8")
    routes = _routes_file(tmp_path)
    for args, bad in ((["--xodr", str(xodr)], xodr), ([], routes)):
        if bad is routes:
            routes.write_text(_after_decl(routes.read_text(), COMMENT_20K + DTD.replace("net", "routes")))
        out = tmp_path / "out"
        code = main(["convert-routes", str(routes), "--out", str(out), *args])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and str(bad) in err[0] and "DOCTYPE" in err[0], err
        assert not out.exists()


# ------------------------------------------------------------------ waypoint numbers
@pytest.mark.parametrize(("attr", "value", "problem"), [
    ("x", "1e309", "x='1e309' is not finite"),
    ("x", "inf", "x='inf' is not finite"),
    ("y", "nan", "y='nan' is not finite"),
    ("x", "-1e400", "x='-1e400' is not finite"),
    ("x", "9" * 400, "(400 characters) is not finite"),
    ("y", "1" + "0" * 300, "(301 characters) is out of range"),
    ("x", "1e300", "x='1e300' is out of range"),
    ("z", "-1e400", "z='-1e400' is not finite"),
    ("pitch", "NaN", "pitch='NaN' is not finite"),
    ("yaw", "1e309", "yaw='1e309' is not finite"),
    ("roll", "1e20", "roll='1e20' is out of range"),
    ("x", "12abc", "x='12abc' is not a number"),
])
def test_waypoint_numbers_out_of_range(tmp_path, attr, value, problem):
    from icrsumo.world.routes import read_routes

    wp = {"x": "1", "y": "2", attr: value}
    attrs = " ".join(f'{k}="{v}"' for k, v in wp.items())
    p = tmp_path / "r.xml"
    p.write_text(f'<routes><route id="r7" town="t"><waypoint x="0" y="0"/><waypoint {attrs}/>'
                 '</route></routes>', encoding="utf-8")
    specs, errors = read_routes(p)
    assert specs == [] and len(errors) == 1
    text = _one_line(errors[0][1], p)
    assert f"{p}: route r7, waypoint 1: attribute {attr}=" in text and problem in text, text


def test_waypoint_numbers_cli_no_warning(tmp_path, capsys):
    p = tmp_path / "r.xml"
    p.write_text('<routes><route id="r" town="icr_rural"><waypoint x="1e308" y="1e308"/>'
                 '<waypoint x="-1e308" y="3"/></route></routes>', encoding="utf-8")
    code = main(["convert-routes", str(p), "--out", str(tmp_path / "o"), "--traffic", "none"])
    err = capsys.readouterr().err
    assert code == 2 and "RuntimeWarning" not in err and "route r, waypoint 0: attribute x='1e308'" in err


# ------------------------------------------------------------------ template banks
@pytest.fixture()
def banks_dir(tmp_path):
    d = tmp_path / "banks"
    shutil.copytree(data_dir("templates"), d)
    return d


def _set(path, *keys):
    """An edit that sets ``data[k0][k1]... = value``."""
    *head, last = keys[:-1]
    value = keys[-1]

    def edit(d):
        for k in head:
            d = d[k]
        d[last] = value
    return edit


_BANK_CASES = [
    ("paraphrase.json", _set(None, "intents", "left", "plain", 3, "text", 42),
     "intents.left.plain[3].text: text must be a string, not int"),
    ("paraphrase.json", _set(None, "intents", "left", "plain", 3, ["Turn left."]),
     "intents.left.plain[3]: entry must be an object, not list"),
    ("paraphrase.json", _set(None, "intents", "left", "plain", 3, None),
     "intents.left.plain[3]: entry must be an object, not null"),
    ("paraphrase.json", _set(None, "intents", "left", "plain", {"a": 1}),
     "intents.left.plain: plain must be a list, not dict"),
    ("paraphrase.json", _set(None, "intents", "left", "distance", []),
     "intents.left.distance: has 0 entries, needs at least 12"),
    ("paraphrase.json", _set(None, "intents", "turn_left", {"plain": [], "distance": []}),
     "intents.turn_left: unknown intent 'turn_left'"),
    ("paraphrase.json", _set(None, "intents", "left", "plain", 0, "weight", 2),
     "intents.left.plain[0].weight: unknown key 'weight'"),
    ("paraphrase.json", _set(None, "intents", "left", "sometimes", []),
     "intents.left.sometimes: unknown form 'sometimes'"),
    ("paraphrase.json", _set(None, "intents", [1, 2]), "intents: intents must be an object, not list"),
    ("paraphrase.json", _set(None, "extra", 1), "extra: unknown key 'extra'"),
    ("misleading.json", _set(None, "format", "icrsumo-bank/9"), "format: unsupported format"),
    ("ambiguity.json", _set(None, "entries", 5, "id", 7), "entries[5].id: id must be a string, not int"),
    ("ambiguity.json", _set(None, "entries", None), "entries: missing list of entries"),
    ("noise.json", _set(None, "operations", 2, "ops", [["lower"]]),
     "operations[2].ops[0]: primitive must be a string, not list"),
    ("noise.json", _set(None, "operations", 2, "ops", "lower"),
     "operations[2].ops: ops must be a list, not str"),
    ("baseline.json", _set(None, "types", "turn", "phrasings", 1, 3.5),
     "types.turn.phrasings[1]: text must be a string, not float"),
    ("baseline.json", _set(None, "types", "turn", "phrasings", {"0": "Turn {dir}."}),
     "types.turn.phrasings: phrasings must be a list, not dict"),
    ("baseline.json", _set(None, "types", "turn_sharp", {"intent": "{dir}", "phrasings": []}),
     "types.turn_sharp: unknown instruction type 'turn_sharp'"),
    ("baseline.json", _set(None, "types", "turn", "intent", "left"), "types.turn.intent: is 'left'"),
    ("baseline.json", _set(None, "types", "start", None), "types.start: missing type"),
]


@pytest.mark.parametrize(("file", "edit", "expect"), _BANK_CASES,
                         ids=[c[2].split(":")[0] + "-" + c[0] for c in _BANK_CASES])
def test_template_bank_wrong_types_and_keys(banks_dir, file, edit, expect):
    from icrsumo.instructions.banks import load_banks

    path = banks_dir / file
    data = json.loads(path.read_text(encoding="utf-8"))
    edit(data)
    path.write_text(json.dumps(data), encoding="utf-8")
    with pytest.raises(InputError) as err:
        load_banks(banks_dir)
    text = _one_line(err.value, path)
    assert f"{path}: {expect}" in text, text


@pytest.mark.parametrize(("encoding", "expect"), [
    ("utf-16", "template bank is UTF-16-encoded, not UTF-8"),
    ("latin-1", "template bank is not UTF-8 text"),
    ("utf-32", "template bank is UTF-32-encoded, not UTF-8"),
])
def test_template_bank_encodings(banks_dir, encoding, expect):
    from icrsumo.instructions.banks import load_banks

    path = banks_dir / "ambiguity.json"
    text = path.read_text(encoding="utf-8").replace("Make a turn", "Make a tourné", 1)
    path.write_bytes(text.encode(encoding))
    with pytest.raises(InputError) as err:
        load_banks(banks_dir)
    assert expect in _one_line(err.value, path)


# ------------------------------------------------------------------ a converted scenario
@pytest.fixture(scope="module")
def converted_one(tmp_path_factory) -> tuple[Path, Path]:
    """One bundled route converted (no traffic) and its instructions (K=1): (scenarios, instructions)."""
    from icrsumo.core.resources import bundled_suites
    from icrsumo.instructions.generate import GenerateOptions, generate
    from icrsumo.world.convert import ConvertOptions, convert_routes
    from icrsumo.world.routes import format_routes, read_routes

    root = tmp_path_factory.mktemp("bad_files")
    specs, _ = read_routes(bundled_suites()["tiny"])
    routes = root / "one.xml"
    routes.write_text(format_routes(specs[:1]), encoding="utf-8")
    rep = convert_routes(routes, root / "sc", ConvertOptions(traffic="none"))
    assert rep.failures == []
    written, failures = generate(root / "sc", root / "instr", GenerateOptions(k=1))
    assert failures == [] and len(written) == 1
    return root / "sc", root / "instr" / f"{written[0]}.json"


def _copy_scenario(converted_one, tmp_path) -> Path:
    """A writable copy of the converted folder; returns the scenario folder in it."""
    dst = tmp_path / "sc"
    shutil.copytree(converted_one[0], dst)
    return next(p for p in (dst / "scenarios").iterdir() if p.is_dir())


def _mutator(path_keys, value):
    def edit(d):
        for k in path_keys[:-1]:
            d = d[k]
        if value is _DEL:
            del d[path_keys[-1]]
        else:
            d[path_keys[-1]] = value
    return edit


_DEL = object()


def test_template_bank_through_generate_cli(converted_one, banks_dir, tmp_path, capsys):
    path = banks_dir / "noise.json"
    path.write_text('{"family": "noise", "operations": {"id": "N1"}}', encoding="utf-8")
    out = tmp_path / "instr"
    code = main(["generate", str(converted_one[0]), "--out", str(out), "--templates", str(banks_dir)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert err[0] == (f"icrsumo: error: {path}: operations: operations must be a list, not dict "
                      "(fix: see templates/README.md for the bank format)")
    assert not out.exists()

_I0 = ("sets", 0, "instructions", 0)
_INSTRUCTION_CASES = [
    (("sets", 1, "family"), "sideways", "sets[1].family: unknown family 'sideways'"),
    ((*_I0, "intent"), "north", "sets[0].instructions[0].intent: unknown intent 'north'"),
    ((*_I0, "trigger"), "10", "sets[0].instructions[0].trigger: trigger must be a number"),
    ((*_I0, "id"), 1.5, "sets[0].instructions[0].id: id must be an integer, not float"),
    ((*_I0, "text"), ["a"], "sets[0].instructions[0].text: text must be a string"),
    (_I0, None, "sets[0].instructions[0]: instructions[0] must be an object, not null"),
    ((*_I0, "distance"), "far", "sets[0].instructions[0].distance: distance must be"),
    ((*_I0, "distance"), "__1e400__",
     "sets[0].instructions[0].distance: distance must be a finite number, not inf"),
    (("sets", 0, "k"), True, "sets[0].k: k must be an integer, not bool"),
    (("sets", 0, "k"), -1, "sets[0].k: k = -1 is out of range"),
    (("sets", 0, "family"), "paraphrase", "sets[0].family: the first set must be the baseline"),
    (("sets",), {"baseline": []}, "sets: sets must be a list, not dict"),
    (("sets",), [], "sets: has 0 entries, needs at least 1"),
    (("sets",), _DEL, "top level: missing key 'sets'"),
    (("route_id",), 7, "route_id: route_id must be a string, not int"),
    (("notices", 0, "intent"), "halt", "notices[0].intent: unknown intent 'halt'"),
    (("notices", 0, "end"), -5.0, "notices[0].end: end = -5.0 is out of range"),
    (("maneuvers", 0, "kind"), "teleport", "maneuvers[0].kind: unknown maneuver kind 'teleport'"),
    (("format",), "icrsumo-instructions/2", "format: unsupported format"),
]


@pytest.mark.parametrize(("keys", "value", "expect"), _INSTRUCTION_CASES,
                         ids=[c[2].split(":")[0] for c in _INSTRUCTION_CASES])
def test_instruction_file_wrong_types(converted_one, tmp_path, keys, value, expect):
    from icrsumo.instructions.store import read_instruction_sets

    doc = json.loads(converted_one[1].read_text(encoding="utf-8"))
    assert doc["notices"] and doc["maneuvers"]
    _mutator(keys, value)(doc)
    p = tmp_path / "route.json"
    p.write_text(json.dumps(doc).replace('"__1e400__"', "1e400"), encoding="utf-8")
    with pytest.raises(InputError) as err:
        read_instruction_sets(p)
    text = _one_line(err.value, p)
    assert f"{p}: {expect}" in text, text


def test_instruction_file_triggers_out_of_order_and_encodings(converted_one, tmp_path):
    from icrsumo.instructions.store import read_instruction_sets

    assert read_instruction_sets(converted_one[1])[0].family == "baseline"
    doc = json.loads(converted_one[1].read_text(encoding="utf-8"))
    ins = doc["sets"][0]["instructions"]
    ins.append(dict(ins[0], id=99, trigger=0.0))
    ins[0]["trigger"] = 5.0
    p = tmp_path / "route.json"
    p.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(InputError, match=r"sets\[0\]\.instructions\[\d+\]\.trigger: trigger 0 comes before"):
        read_instruction_sets(p)
    p.write_bytes(converted_one[1].read_text(encoding="utf-8").encode("utf-16"))
    with pytest.raises(InputError, match="UTF-16"):
        read_instruction_sets(p)


_SCENARIO_CASES = [
    (("ego", "start", "pos"), "7", "ego.start.pos: pos must be a number, not str"),
    (("ego", "start", "lane"), "nolaneindex", "ego.start.lane: lane 'nolaneindex' is not a SUMO lane id"),
    (("ego", "start", "speed"), 3, "ego.start.speed: unknown key 'speed'"),
    (("ego", "edges"), [], "ego.edges: has 0 entries, needs at least 1"),
    (("ego", "edges", 0), 12, "ego.edges[0]: edges[0] must be a string, not int"),
    (("ego", "lanes"), [[0], [1], [2], [3], [4], [5], [6], [7], [8], [9]], "ego.lanes: has 10 entries"),
    (("ego", "lanes", 0), [[0]], "ego.lanes[0][0]: lanes[0][0] must be an integer, not list"),
    (("ego", "length"), 0, "ego.length: length = 0 is out of range"),
    (("ego", "depart"), "__1e400__", "ego.depart: depart must be a finite number, not inf"),
    (("junctions", 0, "direction"), "sideways", "junctions[0].direction: unknown SUMO direction 'sideways'"),
    (("junctions", 0, "choice"), "yes", "junctions[0].choice: choice must be true or false, not str"),
    (("junctions", 0, "from_lane"), -1, "junctions[0].from_lane: from_lane = -1 is out of range"),
    (("junctions",), {"J": 1}, "junctions: junctions must be a list, not dict"),
    (("lane_changes",), [{"edge": "e", "pos": 1.0, "from_lane": 0, "to_lane": "1"}],
     "lane_changes[0].to_lane: to_lane must be an integer, not str"),
    (("route", "polyline"), [[0, 0], [1]], "route.polyline[1]: must be [x, y], not 1 numbers"),
    (("route", "polyline", 0, 0), 10 ** 400, "route.polyline[0][0]: polyline[0][0] must be a finite number"),
    (("route", "length"), None, "route.length: length must be a number, not null"),
    (("waypoints",), [[0, 0]], "waypoints: has 1 entries, needs at least 2"),
    (("waypoints", 1), [1, 2, 3], "waypoints[1]: must be [x, y], not 3 numbers"),
    (("seed",), -3, "seed: seed = -3 is out of range"),
    (("step_length",), 0, "step_length: step_length = 0 is out of range"),
    (("traffic", "level"), "gridlock", "traffic.level: unknown traffic level 'gridlock'"),
    (("traffic", "n_vehicles"), "3", "traffic.n_vehicles: n_vehicles must be an integer, not str"),
    (("traffic",), _DEL, "top level: missing key 'traffic'"),
    (("weather",), ["ClearNoon"], "weather: weather must be an object, not list"),
    (("route_id",), "", "route_id: route_id must not be empty"),
    (("net",), "../../networks/missing.net.xml", "net: network '../../networks/missing.net.xml' not found"),
    (("sumocfg",), "nope.sumocfg", "sumocfg: SUMO config 'nope.sumocfg' not found"),
    (("format",), "icrsumo-scenario/0", "format: unsupported format"),
]


@pytest.mark.parametrize(("keys", "value", "expect"), _SCENARIO_CASES,
                         ids=[c[2].split(":")[0] for c in _SCENARIO_CASES])
def test_scenario_manifest_wrong_types(converted_one, tmp_path, keys, value, expect):
    from icrsumo.world.scenario import read_scenario

    sc = _copy_scenario(converted_one, tmp_path)
    mpath = sc / "scenario.json"
    doc = json.loads(mpath.read_text(encoding="utf-8"))
    _mutator(keys, value)(doc)
    mpath.write_text(json.dumps(doc).replace('"__1e400__"', "1e400"), encoding="utf-8")
    with pytest.raises(InputError) as err:
        read_scenario(sc)
    text = _one_line(err.value, mpath)
    assert f"{mpath}: {expect}" in text, text


def test_scenario_sumo_files_missing_or_hostile(converted_one, tmp_path, capsys):
    from icrsumo.world.scenario import read_scenario

    sc = _copy_scenario(converted_one, tmp_path)
    read_scenario(sc)  # the copy is whole
    cfg, ego = sc / "scenario.sumocfg", sc / "ego.rou.xml"
    good, ego_text = cfg.read_text(encoding="utf-8"), ego.read_text()
    option_edits = [
        ('<step-length value="0.05"/>', '<step-length value="fast"/>',
         "<step-length value='fast'>: is not a number"),
        ('<step-length value="0.05"/>', '<step-length value="0.1"/>',
         "differs from the manifest's step_length"),
        ('<begin value="0"/>', '<begin value="1e9"/>', "is not in [0, 1e+07]"),
        ('<collision.action value="warn"/>', '<collision.action value="remove"/>', "must be warn"),
        ('<no-warnings value="true"/>', '<no-warnings value="yes"/>', "must be true or false"),
        ('.net.xml"/>', '.net.xml,other.net.xml"/>', "not the manifest's network"),
    ]
    for before, _, _ in option_edits:
        assert before in good, before
    # (file, its damaged text, the message), each file restored after its case
    cases = [
        (cfg, good.replace('value="ego.rou.xml"', 'value="ego.rou.xml,gone.rou.xml"'),
         r"scenario.sumocfg: <route-files>: names 'gone.rou.xml', which"),
        (cfg, good.replace("<report>", '<output><fcd-output value="/tmp/fcd.xml"/></output><report>'),
         r"scenario.sumocfg: <output>: is not an option a scenario may set"),
        (cfg, _after_decl(good, COMMENT_20K + DTD.replace("net", "configuration")),
         f"scenario.sumocfg: line 3: SUMO config {BAN}"),
        *[(cfg, good.replace(before, after), re.escape(expect)) for before, after, expect in option_edits],
        (ego, ego_text.replace("</routes>", '<edgeData id="d" file="/tmp/x.xml"/></routes>'),
         r"ego.rou.xml: <edgeData>: is not a demand element"),
        (ego, ego_text.replace("</routes>", '<vehicle id="v" route="ego_route" depart="1e6"/></routes>'),
         r"ego.rou.xml: <vehicle id='v' depart='1e6'>: is not a time"),
        (ego, ego_text[: len(ego_text) // 2], r"ego.rou.xml: line \d+, column \d+: malformed XML"),
        (ego, _after_decl(ego_text, COMMENT_20K + DTD.replace("net", "routes")),
         f"ego.rou.xml: line 3: SUMO route file {BAN}"),
    ]
    for path, text, pattern in cases:
        path.write_text(text)
        with pytest.raises(InputError, match=pattern):
            read_scenario(sc)
        path.write_text(good if path == cfg else ego_text)
    net = sc.parent.parent / "networks" / "icr_arterial.net.xml"
    net.write_text(_after_decl(net.read_text(), COMMENT_20K + DTD))
    with pytest.raises(InputError, match=f"icr_arterial.net.xml: line 3: network file {BAN}"):
        read_scenario(sc)
    # and through the CLI: one line, exit 2
    code = main(["generate", str(sc.parent.parent), "--out", str(tmp_path / "instr"), "--k", "1"])
    err = capsys.readouterr().err
    assert code == 2 and f"network file {BAN}" in err and "Traceback" not in err


@pytest.mark.parametrize(("edit", "expect"), [
    (lambda d: d.update(scenarios={"a": 1}), "scenarios: scenarios must be a list, not dict"),
    (lambda d: d["scenarios"][0].update(dir="../../etc"), "scenarios[0].dir: '../../etc' is not a folder"),
    (lambda d: d["scenarios"][0].update(dir="/etc"), "scenarios[0].dir: '/etc' is not a folder inside"),
    (lambda d: d["scenarios"][0].update(dir="scenarios/gone"), "scenarios[0].dir: 'scenarios/gone' holds no"),
    (lambda d: d["scenarios"][0].pop("dir"), "scenarios[0]: missing key 'dir'"),
    (lambda d: d["scenarios"].__setitem__(0, "scenarios/x"), "scenarios[0]: scenarios[0] must be an object"),
    (lambda d: d.update(format="something/1"), "format: unsupported format 'something/1'"),
])
def test_scenario_index_damaged(converted_one, tmp_path, edit, expect):
    from icrsumo.world.scenario import find_scenarios

    sc = _copy_scenario(converted_one, tmp_path)
    index = sc.parent.parent / "index.json"
    doc = json.loads(index.read_text(encoding="utf-8"))
    edit(doc)
    index.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(InputError) as err:
        find_scenarios(index.parent)
    text = _one_line(err.value, index)
    assert f"{index}: {expect}" in text, text


# ------------------------------------------------------------------ episode logs
@pytest.mark.parametrize(("edit", "expect"), [
    (lambda d: d.update(k="1"), "k: expected an integer, got '1'"),
    (lambda d: d["steps"]["x"].__setitem__(0, 10 ** 400), "steps.x[0]: expected a finite number, got 1000"),
    (lambda d: d["steps"].update(t={"0": 0.0}), "steps.t: expected a list, got dict"),
    (lambda d: d.update(events=[["collision_vehicle", 1.0]]), "events[0]: expected a list [kind, t, pos"),
    (lambda d: d.update(family="bogus"), "family: unknown family 'bogus'"),
    (lambda d: d.update({"x" * 500: 1}), "unknown key 'xxxxxxxx"),
    (lambda d: d.update(steps=None), "steps: expected an object"),
])
def test_episode_log_wrong_types(tmp_path, edit, expect):
    from results.test_logs import make_log

    from icrsumo.results.logs import log_to_dict, read_log

    d = log_to_dict(make_log())
    edit(d)
    p = tmp_path / "ep.json"
    p.write_text(json.dumps(d), encoding="utf-8")
    with pytest.raises(InputError) as err:
        read_log(p)
    text = _one_line(err.value, p)
    assert expect in text, text


@pytest.mark.parametrize(("raw", "expect"), [
    ("utf-16", "episode log is UTF-16-encoded"),
    ("latin-1", "episode log is not UTF-8"),
    ("nested", "nested too deeply"),
    ("folder", "cannot read episode log: it is a folder"),
])
def test_episode_log_encodings(tmp_path, raw, expect):
    from results.test_logs import make_log

    from icrsumo.results.logs import dumps_log, read_log

    p = tmp_path / "ep.json"
    text = dumps_log(make_log()).replace('"agent": "', '"agent": "é', 1)
    if raw == "folder":
        p.mkdir()
    elif raw == "nested":
        p.write_text("[" * 200_000 + "]" * 200_000)
    else:
        p.write_bytes(text.encode(raw))
    with pytest.raises(InputError) as err:
        read_log(p)
    assert expect in _one_line(err.value, p)


# ------------------------------------------------------------------ --baseline-bank
@pytest.mark.parametrize(("content", "expect"), [
    ('{"0": "Turn left."}', '"0": must be a non-empty list of phrasings'),
    ('{"0": {"a": "Turn left."}}', '"0": must be a non-empty list of phrasings'),
    ('{"0": [["Turn left."]]}', '"0"[0]: phrasing must be a non-empty string'),
    ('{"0": [null]}', '"0"[0]: phrasing must be a non-empty string'),
    ('{"0": [3]}', '"0"[0]: phrasing must be a non-empty string'),
    ('{"0": []}', '"0": must be a non-empty list of phrasings'),
    ('{"99": ["x"]}', "key '99': not a LangAuto instruction-type id"),
    ('["Turn left."]', "top level: must be a JSON object, not list"),
    ('{"0": ["Turn left."], "0": ["Turn left now."]}', "duplicate key '0'"),
    (b'\xff\xfe{\x00}\x00', "is UTF-16"),
    ('{"0": ["Tourné à gauche."]}'.encode("latin-1"), "not UTF-8"),
    ("[" * 100_000, "nested too deeply"),
])
def test_baseline_bank_wrong_types_and_encodings(tmp_path, content, expect):
    from icrsumo.instructions.baseline_bank import load_baseline_bank

    p = tmp_path / "instruction_dict.json"
    p.write_bytes(content if isinstance(content, bytes) else content.encode("utf-8"))
    with pytest.raises(InputError) as err:
        load_baseline_bank(p)
    assert expect in _one_line(err.value, p)
