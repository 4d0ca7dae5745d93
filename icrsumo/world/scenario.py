"""Scenario manifests: the converted, runnable form of one route (``scenario.json``).

:func:`read_scenario` checks every key the package reads (types, ranges, enum values) and that
the network, the SUMO config and the files the config names exist and are safe XML
(:func:`icrsumo.world.routes.check_xml_file`), so that a damaged or hand-edited scenario folder is one
:class:`~icrsumo.core.errors.InputError` line naming the file and the key, never a traceback later.
What it read is a :class:`Scenario` of frozen records (the ego, its route with the junctions it
crosses, the traffic): the package reads those, never the manifest's keys.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

from icrsumo.core.doccheck import DocChecker
from icrsumo.core.errors import InputError, short
from icrsumo.core.fsio import read_json_doc
from icrsumo.core.types import EgoRoute, JunctionPass, LaneChange, LanePos

from .routes import check_xml_file, parse_xml_file

SCENARIO_FORMAT = "icrsumo-scenario/1"
#: simulation step length (s) written into the .sumocfg: 20 Hz, as the CARLA Leaderboard
STEP_LENGTH = 0.05
INDEX_FORMAT = "icrsumo-index/1"
MANIFEST = "scenario.json"
_FIX = "run icrsumo convert-routes again"
#: SUMO connection directions (JunctionPass.direction)
DIRECTIONS = ("s", "l", "r", "t", "L", "R")
#: traffic levels (icrsumo.world.traffic.TRAFFIC_LEVELS, not imported: that module loads SUMO's tools)
_TRAFFIC_LEVELS = ("none", "light", "normal", "dense")


@dataclass(frozen=True)
class EgoVehicle:
    """The ego vehicle: the ids of its SUMO vType and route (``ego.rou.xml``), the simulation
    time at which it enters (``depart``, s: background traffic warms up before) and its size (m)."""

    vtype: str
    sumo_route: str
    depart: float
    length: float
    width: float


@dataclass(frozen=True)
class Traffic:
    """The background traffic: the simulation runs until ``end`` (s); ``level`` (none, light,
    normal, dense); the vehicles and pedestrians its route files hold and the fleet cap
    (``max_vehicles``, -1: no background vehicles). Scenarios written before icrsumo recorded
    them have "" and None."""

    end: float
    level: str = ""
    n_vehicles: int | None = None
    n_pedestrians: int | None = None
    max_vehicles: int | None = None


@dataclass(frozen=True)
class Scenario:
    """One runnable scenario. Paths are absolute; lengths in m, times in s, angles in rad.

    ``ego``: the ego vehicle; ``route``: its route (edges, lanes, start and end, centre line,
    the junctions it crosses and the lane changes it needs; ``route.headings`` is empty in
    scenarios written before icrsumo recorded it); ``traffic``: the background traffic;
    ``step_length``: the simulation step (s); ``source_hash``: the hash of the inputs it was
    converted from ("" when absent). ``key_points``: the route file's waypoints (m, SUMO's
    frame; their heights are not kept), () in manifests written without them. ``manifest`` is
    the raw ``scenario.json``, for copying it whole; read the records instead of its keys.
    """

    route_id: str
    town: str
    dir: Path
    net: Path
    sumocfg: Path
    seed: int
    step_length: float
    ego: EgoVehicle
    route: EgoRoute
    traffic: Traffic
    weather: dict
    source_hash: str
    manifest: dict
    key_points: tuple[tuple[float, float], ...] = ()

    @property
    def ego_edges(self) -> tuple[str, ...]:
        """The ego's normal edges in order."""
        return self.route.edges

    @property
    def start_lane(self) -> str:
        return self.route.start.lane

    @property
    def start_pos(self) -> float:
        return self.route.start.pos

    @property
    def start(self) -> tuple[float, float, float]:
        """(x, y, heading) of the ego's front at the route start."""
        st = self.route.start
        return st.x, st.y, st.heading

    @property
    def polyline(self) -> tuple[tuple[float, float], ...]:
        """(N, 2) route centre line."""
        return self.route.polyline

    @property
    def headings(self) -> tuple[float, ...]:
        """(N,) lane direction at each polyline vertex (empty in older scenarios)."""
        return self.route.headings

    @property
    def length(self) -> float:
        return self.route.length

    @property
    def ego_depart(self) -> float:
        return self.ego.depart

    @property
    def end_time(self) -> float:
        return self.traffic.end


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


def _lane_pos(c: DocChecker, v: Any, place: str) -> LanePos:
    d = c.obj(v, place)
    extra = sorted(set(d) - {"lane", "pos", "x", "y", "heading"})
    if extra:
        raise c.fail(f"{place}.{extra[0]}", f"unknown key {short(extra[0])}", "keep lane, pos, x, y, heading")
    lane = c.string(c.key(d, "lane", place), f"{place}.lane", nonempty=True)
    edge, _, index = lane.rpartition("_")
    if not edge or not index.isdigit():
        raise c.fail(f"{place}.lane", f"lane {short(lane)} is not a SUMO lane id (<edge>_<index>)")
    pos = c.number(c.key(d, "pos", place), f"{place}.pos", lo=0.0)
    x, y, heading = (c.number(c.key(d, k, place), f"{place}.{k}") for k in ("x", "y", "heading"))
    return LanePos(lane, pos, x, y, heading)


def _ego(c: DocChecker, ego: dict) -> EgoVehicle:
    vtype, sumo_route = (c.string(c.key(ego, k, "ego"), f"ego.{k}", nonempty=True)
                         for k in ("vtype", "route"))
    # convert-routes' --warmup range
    depart = c.number(c.key(ego, "depart", "ego"), "ego.depart", 0.0, 3600.0)
    length, width = (c.number(c.key(ego, k, "ego"), f"ego.{k}", 0.0, 100.0, lo_open=True)
                     for k in ("length", "width"))
    return EgoVehicle(vtype, sumo_route, depart, length, width)


def _lanes(c: DocChecker, ego: dict) -> tuple[tuple[str, ...], tuple[tuple[int, ...], ...], tuple[int, ...]]:
    """The ego's edges, the lanes of each it may continue from and the lane it drives on each."""
    edges = c.lst(c.key(ego, "edges", "ego"), "ego.edges", 1)
    names = tuple(c.string(e, f"ego.edges[{i}]", nonempty=True) for i, e in enumerate(edges))
    out = []
    for key in ("lanes", "lane_path"):
        items = c.lst(c.key(ego, key, "ego"), f"ego.{key}")
        if len(items) != len(edges):
            raise c.fail(f"ego.{key}", f"has {len(items)} entries but ego.edges has {len(edges)}")
        out.append(tuple(c.integer(v, f"ego.lane_path[{i}]", 0, 1000) if key == "lane_path" else
                         tuple(c.integer(x, f"ego.lanes[{i}][{j}]", 0, 1000)
                               for j, x in enumerate(c.lst(v, f"ego.lanes[{i}]")))
                         for i, v in enumerate(items)))
    return names, out[0], out[1]


def _xy_points(c: DocChecker, v: Any, place: str) -> tuple[tuple[float, float], ...]:
    """The list of [x, y] points (m) at ``place``, at least two."""
    points = []
    for i, p in enumerate(c.lst(v, place, 2)):
        pt = c.lst(p, f"{place}[{i}]")
        if len(pt) != 2:
            raise c.fail(f"{place}[{i}]", f"must be [x, y], not {len(pt)} numbers")
        points.append(tuple(c.number(x, f"{place}[{i}][{k}]") for k, x in enumerate(pt)))
    return tuple(points)


def _polyline(c: DocChecker, route: dict) -> tuple[tuple[tuple[float, float], ...], tuple[float, ...]]:
    """The route's centre line and the lane heading at each of its points (() when absent)."""
    poly = c.key(route, "polyline", "route")
    points = _xy_points(c, poly, "route.polyline")
    if "headings" not in route:
        return points, ()
    heads = c.lst(route["headings"], "route.headings")
    if len(heads) != len(poly):
        raise c.fail("route.headings", f"has {len(heads)} entries for {len(poly)} polyline points")
    return points, tuple(c.number(h, f"route.headings[{i}]") for i, h in enumerate(heads))


def _lane_indices(c: DocChecker, d: dict, place: str) -> tuple[int, int]:
    """``from_lane`` and ``to_lane`` of the object ``d`` at ``place``."""
    return c.integer(c.key(d, "from_lane", place), f"{place}.from_lane", 0, 1000), \
        c.integer(c.key(d, "to_lane", place), f"{place}.to_lane", 0, 1000)


def _junction(c: DocChecker, j: Any, place: str) -> JunctionPass:
    j = c.obj(j, place)
    junction, junction_type, from_edge, to_edge, via = (
        c.string(c.key(j, k, place), f"{place}.{k}")
        for k in ("junction", "junction_type", "from_edge", "to_edge", "via"))
    from_lane, to_lane = _lane_indices(c, j, place)
    direction = c.choice(c.key(j, "direction", place), f"{place}.direction", DIRECTIONS, "SUMO direction")
    choice, roundabout = (c.boolean(c.key(j, k, place), f"{place}.{k}") for k in ("choice", "roundabout"))
    pos = c.number(c.key(j, "pos", place), f"{place}.pos", 0.0)
    return JunctionPass(junction, junction_type, from_edge, to_edge, from_lane, to_lane, via, direction,
                        choice, roundabout, pos)


def _lane_change(c: DocChecker, lc: Any, place: str) -> LaneChange:
    lc = c.obj(lc, place)
    edge = c.string(c.key(lc, "edge", place), f"{place}.edge")
    pos = c.number(c.key(lc, "pos", place), f"{place}.pos", 0.0)
    from_lane, to_lane = _lane_indices(c, lc, place)
    if "direction" in lc:
        c.choice(lc["direction"], f"{place}.direction", ("left", "right"), "lane-change direction")
    return LaneChange(edge, pos, from_lane, to_lane)


def _route(c: DocChecker, m: dict, ego: dict) -> EgoRoute:
    """The ego's route: its lanes and ends (``ego``), centre line (``route``), the junctions it
    crosses and the lane changes it needs."""
    edges, lanes, lane_path = _lanes(c, ego)
    start, end = (_lane_pos(c, c.key(ego, k, "ego"), f"ego.{k}") for k in ("start", "end"))
    route = c.obj(c.key(m, "route"), "route")
    length = c.number(c.key(route, "length", "route"), "route.length", 0.0)
    if "timeout" in route:
        c.number(route["timeout"], "route.timeout", 0.0)
    polyline, headings = _polyline(c, route)
    junctions = tuple(_junction(c, j, f"junctions[{i}]")
                      for i, j in enumerate(c.lst(c.key(m, "junctions"), "junctions")))
    changes = tuple(_lane_change(c, lc, f"lane_changes[{i}]")
                    for i, lc in enumerate(c.lst(c.key(m, "lane_changes"), "lane_changes")))
    return EgoRoute(edges=edges, lanes=lanes, lane_path=lane_path, start=start, end=end, polyline=polyline,
                    length=length, junctions=junctions, lane_changes=changes, headings=headings)


def _count(c: DocChecker, d: dict, key: str, lo: int) -> int | None:
    """``traffic.<key>``, a whole number >= ``lo``, or None when absent."""
    return c.integer(d[key], f"traffic.{key}", lo) if key in d else None


def _traffic(c: DocChecker, m: dict) -> Traffic:
    traffic = c.obj(c.key(m, "traffic"), "traffic")
    level = c.choice(traffic["level"], "traffic.level", _TRAFFIC_LEVELS, "traffic level") \
        if "level" in traffic else ""
    end = c.number(c.key(traffic, "end", "traffic"), "traffic.end", 0.0, 1e7, lo_open=True)
    return Traffic(end, level, _count(c, traffic, "n_vehicles", 0), _count(c, traffic, "n_pedestrians", 0),
                   _count(c, traffic, "max_vehicles", -1))


def _header(c: DocChecker, m: dict) -> tuple[str, str, int, float, dict]:
    """The manifest's route id, town, seed, step length (s) and weather."""
    route_id = c.string(c.key(m, "route_id"), "route_id", nonempty=True, limit=200)
    town = c.string(c.key(m, "town"), "town", limit=200)
    seed = c.integer(c.key(m, "seed"), "seed", 0, 2**31 - 1)
    step_length = c.number(m["step_length"], "step_length", 0.0, 1.0, lo_open=True) \
        if "step_length" in m else STEP_LENGTH
    weather = c.obj(c.key(m, "weather"), "weather")
    for k, v in weather.items():
        c.string(v, f"weather.{k}", limit=1000)
    return route_id, town, seed, step_length, dict(weather)


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
    route_id, town, seed, step_length, weather = _header(c, m)
    ego = c.obj(c.key(m, "ego"), "ego")
    vehicle, route, traffic = _ego(c, ego), _route(c, m, ego), _traffic(c, m)
    source_hash = c.string(m["source_hash"], "source_hash") if "source_hash" in m else ""
    key_points = _xy_points(c, m["waypoints"], "waypoints") if "waypoints" in m else ()
    base = mpath.parent
    net = _rel_file(c, base, c.key(m, "net"), "net", "network")
    check_xml_file(net, "network file", _FIX)
    sumocfg = _rel_file(c, base, c.key(m, "sumocfg"), "sumocfg", "SUMO config")
    _check_sumocfg(sumocfg, sumocfg, net, step_length)
    return Scenario(route_id=route_id, town=town, dir=base, net=net, sumocfg=sumocfg, seed=seed,
                    step_length=step_length, ego=vehicle, route=route, traffic=traffic, weather=weather,
                    source_hash=source_hash, manifest=m, key_points=key_points)


def check_against_net(sc: Scenario, net) -> None:
    """InputError unless every edge and lane the manifest of ``sc`` names is a passenger-car
    edge / lane of ``net`` (a :class:`~icrsumo.world.networks.RoadNet`): a manifest edited by hand or
    paired with another network fails here, naming the key, not later in SUMO."""
    route, c = sc.route, DocChecker(sc.dir / MANIFEST, _FIX)

    def edge(e: str, place: str) -> None:
        if e not in net.passenger_lanes:
            raise c.fail(place, f"edge {short(e)} is not a car edge of {net.path.name}",
                         f"{_FIX} (the manifest and its network disagree)")

    for i, e in enumerate(route.edges):
        edge(e, f"ego.edges[{i}]")
    for k, end in (("start", route.start), ("end", route.end)):
        if end.lane not in net.lane_shape:
            raise c.fail(f"ego.{k}.lane", f"lane {short(end.lane)} is not a car lane of {net.path.name}",
                         f"{_FIX} (the manifest and its network disagree)")
    for i, j in enumerate(route.junctions):
        edge(j.from_edge, f"junctions[{i}].from_edge")
        edge(j.to_edge, f"junctions[{i}].to_edge")
    for i, lc in enumerate(route.lane_changes):
        edge(lc.edge, f"lane_changes[{i}].edge")


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
