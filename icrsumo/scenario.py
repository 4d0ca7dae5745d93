"""Scenario manifests: the converted, runnable form of one route (``scenario.json``).

:func:`read_scenario` checks every key the package reads (types, ranges, enum values) and that
the network, the SUMO config and the files the config names exist and are safe XML
(:func:`icrsumo.routes.check_xml_file`), so that a damaged or hand-edited scenario folder is one
:class:`~icrsumo.errors.InputError` line naming the file and the key, never a traceback later.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

from .errors import InputError, expect, short
from .fsio import read_json_doc
from .routes import check_xml_file, parse_xml_file

SCENARIO_FORMAT = "icrsumo-scenario/1"
#: simulation step length (s) written into the .sumocfg: 20 Hz, as the CARLA Leaderboard
STEP_LENGTH = 0.05
INDEX_FORMAT = "icrsumo-index/1"
MANIFEST = "scenario.json"
_FIX = "run icrsumo convert-routes again"
#: SUMO connection directions (JunctionPass.direction)
DIRECTIONS = ("s", "l", "r", "t", "L", "R")
#: traffic levels (icrsumo.traffic.TRAFFIC_LEVELS, not imported: that module loads SUMO's tools)
_TRAFFIC_LEVELS = ("none", "light", "normal", "dense")


class DocChecker:
    """Typed reads of a parsed JSON document ``file``; each problem is an InputError naming the
    file and the key path (``ego.start.pos``, ``sets[2].instructions[0].intent``) with ``fix``."""

    def __init__(self, file: object, fix: str) -> None:
        self.file, self.fix = file, fix

    def fail(self, place: str, problem: str, fix: str | None = None) -> InputError:
        return InputError(self.file, place, problem, self.fix if fix is None else fix)

    @staticmethod
    def _name(place: str) -> str:
        return place.rsplit(".", 1)[-1] or "value"

    def key(self, d: dict, key: str, prefix: str = "") -> Any:
        """``d[key]`` (``prefix`` is the place of ``d``); a missing key is an error."""
        if key not in d:
            raise self.fail(prefix or "top level", f"missing key {key!r}")
        return d[key]

    def obj(self, v: Any, place: str) -> dict:
        return expect(v, dict, self.file, place, self._name(place), self.fix)

    def lst(self, v: Any, place: str, min_len: int = 0) -> list:
        expect(v, list, self.file, place, self._name(place), self.fix)
        if len(v) < min_len:
            raise self.fail(place, f"has {len(v)} entries, needs at least {min_len}")
        return v

    def string(self, v: Any, place: str, nonempty: bool = False, limit: int = 10_000) -> str:
        expect(v, str, self.file, place, self._name(place), self.fix)
        if nonempty and not v.strip():
            raise self.fail(place, f"{self._name(place)} must not be empty")
        if len(v) > limit:
            raise self.fail(place, f"{self._name(place)} is {len(v)} characters long (at most {limit})")
        return v

    def boolean(self, v: Any, place: str) -> bool:
        return expect(v, bool, self.file, place, self._name(place), self.fix)

    def integer(self, v: Any, place: str, lo: int | None = None, hi: int | None = None) -> int:
        expect(v, int, self.file, place, self._name(place), self.fix)
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            rng = f"{lo if lo is not None else '-inf'} .. {hi if hi is not None else 'inf'}"
            raise self.fail(place, f"{self._name(place)} = {short(v)} is out of range ({rng})")
        return v

    def number(self, v: Any, place: str, lo: float | None = None, hi: float | None = None,
               lo_open: bool = False) -> float:
        """A finite JSON number (an integer is fine) within [lo, hi] (``lo_open``: > lo)."""
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            got = "null" if v is None else type(v).__name__
            raise self.fail(place, f"{self._name(place)} must be a number, not {got}")
        try:
            f = float(v)
        except OverflowError:
            f = math.inf
        if not math.isfinite(f):
            raise self.fail(place, f"{self._name(place)} must be a finite number, not {short(v)}")
        below = lo is not None and (f <= lo if lo_open else f < lo)
        if below or (hi is not None and f > hi):
            left = "(" if lo_open else "["
            raise self.fail(place, f"{self._name(place)} = {short(v)} is out of range "
                            f"({left}{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}])")
        return f

    def choice(self, v: Any, place: str, values, what: str) -> str:
        """``v`` as one of the strings ``values`` (an enum class or a sequence)."""
        text = expect(v, str, self.file, place, self._name(place), self.fix)
        allowed = [str(x) for x in values]
        if text not in allowed:
            raise self.fail(place, f"unknown {what} {short(text)}", f"use one of {', '.join(allowed)}")
        return text


@dataclass(frozen=True)
class Scenario:
    """One runnable scenario. Paths are absolute; lengths in m, times in s, angles in rad.

    ``ego_edges``: the ego's normal edges in order; ``polyline``: (N, 2) route centre line;
    ``headings``: (N,) lane direction at each polyline vertex (rad; empty in scenarios written
    before icrsumo recorded it);
    ``start``: (x, y, heading) of the ego at the route start; ``ego_depart``: simulation time
    at which the ego enters (background traffic warms up before).
    """

    route_id: str
    town: str
    dir: Path
    net: Path
    sumocfg: Path
    seed: int
    ego_edges: tuple[str, ...]
    start_lane: str
    start_pos: float
    start: tuple[float, float, float]
    polyline: tuple[tuple[float, float], ...]
    length: float
    ego_depart: float
    end_time: float
    weather: dict
    manifest: dict
    headings: tuple[float, ...] = ()


def _rel_file(c: DocChecker, base: Path, value: Any, place: str, what: str) -> Path:
    """A file named relative to ``base`` by key ``place``: it must exist and be a file."""
    rel = c.string(value, place, nonempty=True, limit=4096)
    if "\x00" in rel:
        raise c.fail(place, f"{what} name {short(rel)} holds a NUL character", _FIX)
    path = (base / rel).resolve()
    if not path.is_file():
        why = "a folder" if path.is_dir() else "no such file"
        raise c.fail(place, f"{what} {short(rel)} not found ({why})", f"{_FIX}, or restore the {what}")
    return path


def _lane_pos(c: DocChecker, v: Any, place: str) -> dict:
    d = c.obj(v, place)
    extra = sorted(set(d) - {"lane", "pos", "x", "y", "heading"})
    if extra:
        raise c.fail(f"{place}.{extra[0]}", f"unknown key {short(extra[0])}", "keep lane, pos, x, y, heading")
    lane = c.string(c.key(d, "lane", place), f"{place}.lane", nonempty=True)
    edge, _, index = lane.rpartition("_")
    if not edge or not index.isdigit():
        raise c.fail(f"{place}.lane", f"lane {short(lane)} is not a SUMO lane id (<edge>_<index>)")
    c.number(c.key(d, "pos", place), f"{place}.pos", lo=0.0)
    for k in ("x", "y", "heading"):
        c.number(c.key(d, k, place), f"{place}.{k}")
    return d


def check_manifest(m: dict, c: DocChecker) -> None:
    """Every key of a scenario manifest that the package reads, with its type and range."""
    c.string(c.key(m, "route_id"), "route_id", nonempty=True, limit=200)
    c.string(c.key(m, "town"), "town", limit=200)
    c.integer(c.key(m, "seed"), "seed", 0, 2**31 - 1)
    if "step_length" in m:
        c.number(m["step_length"], "step_length", 0.0, 1.0, lo_open=True)
    weather = c.obj(c.key(m, "weather"), "weather")
    for k, v in weather.items():
        c.string(v, f"weather.{k}", limit=1000)
    ego = c.obj(c.key(m, "ego"), "ego")
    for k in ("vtype", "route"):
        c.string(c.key(ego, k, "ego"), f"ego.{k}", nonempty=True)
    c.number(c.key(ego, "depart", "ego"), "ego.depart", 0.0, 3600.0)  # convert-routes' --warmup range
    for k in ("length", "width"):
        c.number(c.key(ego, k, "ego"), f"ego.{k}", 0.0, 100.0, lo_open=True)
    edges = c.lst(c.key(ego, "edges", "ego"), "ego.edges", 1)
    for i, e in enumerate(edges):
        c.string(e, f"ego.edges[{i}]", nonempty=True)
    for key in ("lanes", "lane_path"):
        items = c.lst(c.key(ego, key, "ego"), f"ego.{key}")
        if len(items) != len(edges):
            raise c.fail(f"ego.{key}", f"has {len(items)} entries but ego.edges has {len(edges)}")
        for i, v in enumerate(items):
            if key == "lane_path":
                c.integer(v, f"ego.lane_path[{i}]", 0, 1000)
                continue
            for j, x in enumerate(c.lst(v, f"ego.lanes[{i}]")):
                c.integer(x, f"ego.lanes[{i}][{j}]", 0, 1000)
    for k in ("start", "end"):
        _lane_pos(c, c.key(ego, k, "ego"), f"ego.{k}")
    route = c.obj(c.key(m, "route"), "route")
    c.number(c.key(route, "length", "route"), "route.length", 0.0)
    if "timeout" in route:
        c.number(route["timeout"], "route.timeout", 0.0)
    poly = c.lst(c.key(route, "polyline", "route"), "route.polyline", 2)
    for i, p in enumerate(poly):
        pt = c.lst(p, f"route.polyline[{i}]")
        if len(pt) != 2:
            raise c.fail(f"route.polyline[{i}]", f"must be [x, y], not {len(pt)} numbers")
        c.number(pt[0], f"route.polyline[{i}][0]")
        c.number(pt[1], f"route.polyline[{i}][1]")
    if "headings" in route:
        heads = c.lst(route["headings"], "route.headings")
        if len(heads) != len(poly):
            raise c.fail("route.headings", f"has {len(heads)} entries for {len(poly)} polyline points")
        for i, h in enumerate(heads):
            c.number(h, f"route.headings[{i}]")
    for i, j in enumerate(c.lst(c.key(m, "junctions"), "junctions")):
        place = f"junctions[{i}]"
        j = c.obj(j, place)
        for k in ("junction", "junction_type", "from_edge", "to_edge", "via"):
            c.string(c.key(j, k, place), f"{place}.{k}")
        for k in ("from_lane", "to_lane"):
            c.integer(c.key(j, k, place), f"{place}.{k}", 0, 1000)
        c.choice(c.key(j, "direction", place), f"{place}.direction", DIRECTIONS, "SUMO direction")
        for k in ("choice", "roundabout"):
            c.boolean(c.key(j, k, place), f"{place}.{k}")
        c.number(c.key(j, "pos", place), f"{place}.pos", 0.0)
    for i, lc in enumerate(c.lst(c.key(m, "lane_changes"), "lane_changes")):
        place = f"lane_changes[{i}]"
        lc = c.obj(lc, place)
        c.string(c.key(lc, "edge", place), f"{place}.edge")
        c.number(c.key(lc, "pos", place), f"{place}.pos", 0.0)
        for k in ("from_lane", "to_lane"):
            c.integer(c.key(lc, k, place), f"{place}.{k}", 0, 1000)
        if "direction" in lc:
            c.choice(lc["direction"], f"{place}.direction", ("left", "right"), "lane-change direction")
    traffic = c.obj(c.key(m, "traffic"), "traffic")
    if "level" in traffic:
        c.choice(traffic["level"], "traffic.level", _TRAFFIC_LEVELS, "traffic level")
    c.number(c.key(traffic, "end", "traffic"), "traffic.end", 0.0, 1e7, lo_open=True)
    if "source_hash" in m:
        c.string(m["source_hash"], "source_hash")


#: the sections of a scenario's .sumocfg and the options it may set (those convert-routes writes)
SUMOCFG_SECTIONS = frozenset({"configuration", "input", "time", "processing", "random_number", "report"})
SUMOCFG_OPTIONS = SUMOCFG_SECTIONS | {
    "net-file", "route-files", "begin", "end", "step-length", "collision.action",
    "collision.check-junctions", "collision.mingap-factor", "time-to-teleport", "time-to-impatience",
    "max-num-vehicles", "seed",
    "no-step-log",
    "duration-log.disable", "no-warnings"}


#: elements a scenario's route files may hold (what convert-routes writes, and SUMO's plain
#: demand elements); anything else (an output such as <edgeData>, an additional) is refused
ROUTE_ELEMENTS = frozenset({"routes", "vType", "route", "vehicle", "trip", "flow", "person", "walk",
                            "personTrip", "ride", "stop", "param"})
_TRUE_FALSE = ("true", "false")


def _check_option(shown: Path, tag: str, value: str, step_length: float) -> None:
    """The value of one option of a scenario's .sumocfg (those that are not files)."""
    place = f"<{tag} value={short(value)}>"

    def number(lo: float, hi: float) -> float:
        try:
            x = float(value)
        except ValueError:
            raise InputError(shown, place, "is not a number", _FIX) from None
        if not (math.isfinite(x) and lo <= x <= hi):
            raise InputError(shown, place, f"is not in [{lo:g}, {hi:g}]", _FIX)
        return x

    if tag in ("begin", "end"):
        number(0.0, 1e7)
    elif tag == "step-length":
        if abs(number(0.0, 1.0) - step_length) > 1e-9:
            raise InputError(shown, place, f"differs from the manifest's step_length {step_length:g} s",
                             _FIX)
    elif tag in ("collision.mingap-factor", "time-to-teleport", "time-to-impatience", "max-num-vehicles"):
        number(-1.0, 1e7)
    elif tag == "seed":
        if not value.isdigit() or int(value) > 2**31 - 1:
            raise InputError(shown, place, "is not a seed (0 to 2**31 - 1)", _FIX)
    elif tag == "collision.action":
        if value != "warn":
            raise InputError(shown, place, "must be warn (icrsumo detects collisions itself)", _FIX)
    elif value not in _TRUE_FALSE:
        raise InputError(shown, place, "must be true or false", _FIX)


def _number_or(value: str | None, default: float) -> float:
    try:
        return float(value) if value is not None else default
    except ValueError:
        return default


def _check_route_file(path: Path, end: float) -> None:
    """A scenario's route file: demand elements only, every departure a time (s) within the
    simulation's ``end``."""
    routes = parse_xml_file(path, expected_root="routes", what="SUMO route file", fix=_FIX)
    for e in routes.iter():
        if e.tag not in ROUTE_ELEMENTS:
            raise InputError(path, f"<{e.tag[:40]}>", "is not a demand element a scenario may hold",
                             f"keep to {', '.join(sorted(ROUTE_ELEMENTS))}")
        depart = e.get("depart")
        if depart is not None:
            t = _number_or(depart, math.nan)
            if not 0.0 <= t <= end:  # NaN (not a time) fails too
                raise InputError(path, f"<{e.tag} id={short(e.get('id', ''))} depart={short(depart)}>",
                                 f"is not a time within the simulation (0 to {end:g} s)", _FIX)


def _check_sumocfg(cfg: Path, shown: Path, net: Path, step_length: float) -> None:
    """The SUMO config parses (safely), sets only the options convert-routes writes, with sane
    values, runs the manifest's network, and every route file it names exists and holds only
    demand elements: ``sumo -c`` reads them all."""
    root = parse_xml_file(cfg, expected_root="configuration", what="SUMO config",
                          fix="use the scenario.sumocfg written by icrsumo convert-routes")
    end_el = root.find("./time/end")
    end = 1e7 if end_el is None else _number_or(end_el.get("value"), 1e7)
    for el in root.iter():
        tag = el.tag if isinstance(el.tag, str) else ""
        if tag not in SUMOCFG_OPTIONS:  # e.g. *-output, which would make SUMO write files
            raise InputError(shown, f"<{tag}>", "is not an option a scenario may set (SUMO reads its config "
                             "as given, outputs and logs included)",
                             f"keep to {', '.join(sorted(SUMOCFG_OPTIONS - SUMOCFG_SECTIONS))}")
        if tag in SUMOCFG_SECTIONS:
            continue
        value = el.get("value")
        if value is None:
            raise InputError(shown, f"<{tag}>", "has no value attribute", _FIX)
        if not tag.endswith(("-file", "-files")):
            _check_option(shown, tag, value, step_length)
            continue
        names = [v.strip() for v in value.split(",") if v.strip()]
        if tag == "net-file" and [(cfg.parent / n).resolve() for n in names] != [net.resolve()]:
            raise InputError(shown, f"<{tag}>", f"names {short(value)}, not the manifest's network "
                             f"{net.name}", _FIX)
        for name in names:
            path = (cfg.parent / name).resolve()
            if not path.is_file():
                raise InputError(shown, f"<{tag}>", f"names {short(name)}, which does not exist",
                                 f"{_FIX}, or restore the file")
            if tag == "net-file":
                check_xml_file(path, "network file", _FIX)
                continue
            _check_route_file(path, end)


def read_scenario(path: Path) -> Scenario:
    """Load a scenario from its folder or its ``scenario.json``; every problem (missing or
    damaged manifest, missing network or SUMO file, unsafe XML) is an InputError."""
    path = Path(path)
    mpath = path / MANIFEST if path.is_dir() else path
    m = read_json_doc(mpath, SCENARIO_FORMAT, "scenario manifest", "run icrsumo convert-routes")
    c = DocChecker(mpath, _FIX)
    check_manifest(m, c)
    base = mpath.parent
    net = _rel_file(c, base, c.key(m, "net"), "net", "network")
    check_xml_file(net, "network file", _FIX)
    sumocfg = _rel_file(c, base, c.key(m, "sumocfg"), "sumocfg", "SUMO config")
    _check_sumocfg(sumocfg, sumocfg, net, float(m.get("step_length", STEP_LENGTH)))
    ego, st = m["ego"], m["ego"]["start"]
    return Scenario(
        route_id=m["route_id"], town=m["town"], dir=base, net=net, sumocfg=sumocfg,
        seed=int(m["seed"]), ego_edges=tuple(ego["edges"]), start_lane=st["lane"],
        start_pos=float(st["pos"]), start=(float(st["x"]), float(st["y"]), float(st["heading"])),
        polyline=tuple((float(x), float(y)) for x, y in m["route"]["polyline"]),
        headings=tuple(float(h) for h in m["route"].get("headings", ())),
        length=float(m["route"]["length"]), ego_depart=float(ego["depart"]),
        end_time=float(m["traffic"]["end"]), weather=dict(m["weather"]), manifest=m,
    )


def check_against_net(sc: Scenario, net) -> None:
    """InputError unless every edge and lane the manifest of ``sc`` names is a passenger-car
    edge / lane of ``net`` (a :class:`~icrsumo.networks.RoadNet`): a manifest edited by hand or
    paired with another network fails here, naming the key, not later in SUMO."""
    m, c = sc.manifest, DocChecker(sc.dir / MANIFEST, _FIX)

    def edge(e: str, place: str) -> None:
        if e not in net.passenger_lanes:
            raise c.fail(place, f"edge {short(e)} is not a car edge of {net.path.name}",
                         f"{_FIX} (the manifest and its network disagree)")

    for i, e in enumerate(m["ego"]["edges"]):
        edge(e, f"ego.edges[{i}]")
    for k in ("start", "end"):
        lane = m["ego"][k]["lane"]
        if lane not in net.lane_shape:
            raise c.fail(f"ego.{k}.lane", f"lane {short(lane)} is not a car lane of {net.path.name}",
                         f"{_FIX} (the manifest and its network disagree)")
    for i, j in enumerate(m["junctions"]):
        edge(j["from_edge"], f"junctions[{i}].from_edge")
        edge(j["to_edge"], f"junctions[{i}].to_edge")
    for i, lc in enumerate(m["lane_changes"]):
        edge(lc["edge"], f"lane_changes[{i}].edge")


def find_scenarios(root: Path) -> list[Path]:
    """Scenario folders below ``root`` in the order of ``index.json`` (else sorted by name).
    A damaged index (wrong types, a folder that is missing or outside ``root``) is an
    InputError naming ``index.json`` and the entry."""
    root = Path(root)
    index = root / "index.json"
    if not index.is_file():
        return sorted(p.parent for p in root.glob(f"**/{MANIFEST}"))
    doc = read_json_doc(index, INDEX_FORMAT, "scenario index", "run icrsumo convert-routes")
    c = DocChecker(index, _FIX)
    out = []
    for i, s in enumerate(c.lst(c.key(doc, "scenarios"), "scenarios")):
        place = f"scenarios[{i}]"
        rel = c.string(c.key(c.obj(s, place), "dir", place), f"{place}.dir", nonempty=True, limit=4096)
        parts = PurePosixPath(rel.replace("\\", "/")).parts
        if rel.startswith(("/", "\\")) or ".." in parts or (len(rel) > 1 and rel[1] == ":"):
            raise c.fail(f"{place}.dir", f"{short(rel)} is not a folder inside {root}",
                         "name scenario folders relative to the index, without '..'")
        if not (root / rel / MANIFEST).is_file():
            raise c.fail(f"{place}.dir", f"{short(rel)} holds no {MANIFEST}",
                         f"{_FIX}, or restore the folder")
        out.append(root / rel)
    return out
