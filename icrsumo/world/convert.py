"""``icrsumo convert-routes``: leaderboard route XML -> runnable SUMO scenarios.

Output layout of ``OUT``::

    OUT/networks/<name>.net.xml          networks the scenarios use (copied / converted once)
    OUT/scenarios/<route id>/scenario.json     the manifest (see README)
    OUT/scenarios/<route id>/scenario.sumocfg  runs in plain ``sumo -c``
    OUT/scenarios/<route id>/ego.rou.xml       ego vType and route ``ego_route``
    OUT/scenarios/<route id>/vehicles.rou.xml  background cars (randomTrips + duarouter)
    OUT/scenarios/<route id>/pedestrians.rou.xml  pedestrians, where the town has sidewalks
    OUT/index.json                       converted scenarios in file order, and failures

Every scenario folder appears whole or not at all (written to a staging folder, then renamed).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import tempfile
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

from icrsumo.core.errors import Field, InputError, check_seed
from icrsumo.core.fsio import (
    OutFolder,
    check_out_dir,
    dumps_json,
    replace_dir_atomic,
    sha256_file,
    write_atomic,
)
from icrsumo.core.procs import spawn_context
from icrsumo.core.resources import bundled_towns
from icrsumo.core.types import RouteSpec

from .networks import convert_xodr, load_net
from .routes import read_routes
from .routing import MatchError, plan_route
from .scenario import MANIFEST, SCENARIO_FORMAT, STEP_LENGTH, read_scenario
from .traffic import TRAFFIC_LEVELS, fleet_cap, make_traffic

#: bump when the scenario output changes for the same input, to invalidate reuse
CONVERTER_VERSION = 3
#: s a background vehicle may stand stuck before SUMO teleports it: below the leaderboard's 180 s
#: "blocked" rule, so a background jam dissolves before it can end the ego's route. The ego's
#: vType sets timeToTeleport="-1": SUMO counts the ego's waiting time like any vehicle's and would
#: otherwise teleport the ego too (measured: two carla-fidelity routes ended so)
TELEPORT_S = 120.0
#: s of waiting after which a background driver at a minor link is fully impatient (SUMO's
#: --time-to-impatience; its default is 180 s): it then takes a gap that makes a car with the
#: right of way brake. A left turner at a permissive green facing a steady oncoming stream
#: otherwise holds its lane for cycle after cycle (its waiting time restarts whenever it creeps),
#: and a queue behind it stands past the leaderboard's 180 s blocked rule
#: (``carla_fidelity_mixed_024``, Town04)
IMPATIENCE_S = 60.0
#: ego vehicle footprint (m), a mid-size car as CARLA's Lincoln MKZ
EGO_LENGTH, EGO_WIDTH = 4.9, 2.1


@dataclass(frozen=True)
class ConvertOptions:
    """Options of one conversion. ``max_snap`` in m, ``warmup`` in s."""

    coords: str = "sumo"
    traffic: str = "normal"
    net: Path | None = None
    xodr: Path | None = None
    net_dir: Path | None = None
    max_snap: float = 10.0
    seed: int = 0
    warmup: float = 20.0
    workers: int = 1

    def check(self) -> None:
        if self.coords not in ("sumo", "carla"):
            raise InputError(Field("coords"), "", f"unknown value {self.coords!r}", "use sumo or carla")
        if self.traffic not in TRAFFIC_LEVELS:
            raise InputError(Field("traffic"), "", f"unknown level {self.traffic!r}",
                             f"use one of {', '.join(TRAFFIC_LEVELS)}")
        if sum(x is not None for x in (self.net, self.xodr, self.net_dir)) > 1:
            raise InputError(f"{Field('net')}/{Field('xodr')}/{Field('net_dir')}", "",
                             "more than one network source given",
                             f"give only one of {Field('net')}, {Field('xodr')}, {Field('net_dir')}")
        if not 0 < self.max_snap <= 1000:
            raise InputError(Field("max_snap"), "", f"{self.max_snap:g} is not in (0, 1000]",
                             "give a distance in metres")
        if not 0 <= self.warmup <= 3600:
            raise InputError(Field("warmup"), "", f"{self.warmup:g} is not in [0, 3600]", "give seconds >= 0")
        if self.workers < 1:
            raise InputError(Field("workers"), "", "must be at least 1", "give a positive count")
        check_seed(self.seed)


@dataclass
class ConvertReport:
    """What a conversion did: scenario folder names converted or reused, and the routes that
    failed: ``errors`` (one InputError each, in file order) and ``failures`` (their lines)."""

    converted: list[str] = field(default_factory=list)
    reused: list[str] = field(default_factory=list)
    errors: list[InputError] = field(default_factory=list)

    @property
    def failures(self) -> list[str]:
        """One line per route that failed (:meth:`InputError.line`)."""
        return [e.line() for e in self.errors]


def route_seed(base: int, route_id: str) -> int:
    """Per-route simulator / traffic seed, stable across machines and Python versions."""
    digest = hashlib.sha256(f"{base}/{route_id}".encode()).digest()
    return int.from_bytes(digest[:4], "big") % 2_000_000_000


def safe_name(route_id: str) -> str:
    """Folder name for a route id (letters, digits, ``-_.`` kept; others become ``_``)."""
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", route_id)
    return name if name not in ("", ".", "..") else f"route_{name}"


def _route_timeout(length_m: float) -> float:
    """Leaderboard route timeout (s): 0.8 s per metre + 5 s."""
    return 0.8 * length_m + 5.0


def _resolve_nets(
    specs: list[RouteSpec], opts: ConvertOptions, routes_file: Path, net_store: Path
) -> tuple[dict[str, tuple[Path, str]], dict[str, InputError]]:
    """Map each route id to (source net path, network name); unresolvable routes -> errors."""
    resolved: dict[str, tuple[Path, str]] = {}
    errors: dict[str, InputError] = {}
    if opts.net is not None:
        load_net(Path(opts.net))  # a user's net is read whole before anything is copied
        name = Path(opts.net).name.removesuffix(".xml").removesuffix(".net")
        return {s.id: (Path(opts.net), name) for s in specs}, errors
    if opts.xodr is not None:
        net = convert_xodr(Path(opts.xodr), net_store)
        return {s.id: (net, Path(opts.xodr).stem) for s in specs}, errors
    towns = bundled_towns()
    for s in specs:
        place = f"route {s.id}"
        if not s.town:
            errors[s.id] = InputError(routes_file, place, "missing attribute 'town'",
                                      f"add town=\"...\" or pass {Field('net')} FILE.net.xml")
            continue
        if opts.net_dir is not None:
            d = Path(opts.net_dir)
            if not d.is_dir():
                raise InputError(d, "", f"{Field('net_dir')} folder not found",
                                 f"check the {Field('net_dir')} path")
            net_file, xodr = d / f"{s.town}.net.xml", d / f"{s.town}.xodr"
            if net_file.is_file():
                try:
                    load_net(net_file)  # read whole before anything is copied
                    resolved[s.id] = (net_file, s.town)
                except InputError as err:
                    errors[s.id] = err
            elif xodr.is_file():
                try:
                    resolved[s.id] = (convert_xodr(xodr, net_store), s.town)
                except InputError as err:
                    errors[s.id] = err
            else:
                errors[s.id] = InputError(
                    routes_file, place, f"town {s.town!r} has no {net_file.name} or {xodr.name} "
                    f"in {d}", "add the town's network there",
                )
        elif s.town in towns:
            resolved[s.id] = (towns[s.town], s.town)
        else:
            errors[s.id] = InputError(
                routes_file, place, f"unknown town {s.town!r}",
                f"use a bundled town ({', '.join(towns)}) or pass {Field('net')} FILE.net.xml, "
                f"{Field('xodr')} FILE.xodr or {Field('net_dir')} DIR",
            )
    return resolved, errors


def _place_net(src: Path, name: str, net_store: Path) -> Path:
    """The copy of network ``src`` inside ``OUT/networks`` (written once, atomically)."""
    if src.parent.resolve() == net_store.resolve():
        return src
    dst = net_store / f"{name}.net.xml"
    if not dst.is_file() or sha256_file(dst) != sha256_file(src):
        write_atomic(dst, src.read_bytes())
    return dst


def _source_hash(spec: RouteSpec, net_sha: str, opts: ConvertOptions) -> str:
    payload = {
        "v": CONVERTER_VERSION, "net": net_sha, "id": spec.id, "town": spec.town,
        "wps": [asdict(w) for w in spec.waypoints], "weather": spec.weather,
        "coords": opts.coords, "traffic": opts.traffic, "snap": opts.max_snap,
        "seed": opts.seed, "warmup": opts.warmup,
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


def sumocfg_xml(net_rel: str, route_files: list[str], seed: int, end: float, max_vehicles: int = -1) -> str:
    """The text of a converted scenario's ``.sumocfg``: network ``net_rel`` and ``route_files``
    (paths as written in the file), SUMO seed ``seed``, simulation end ``end`` (s), the
    background fleet capped at ``max_vehicles`` (-1: no cap), and the benchmark's fixed
    processing options (step length, collisions, teleports, impatience)."""
    # collision.mingap-factor 0: a collision is a contact (gap < 0); SUMO's default also counts a
    # same-lane gap below the follower's minGap (2.5 m), which is no contact (see README,
    # *Fidelity on CARLA's towns*). max-num-vehicles caps the background fleet (traffic.fleet_cap;
    # the ego is placed with moveToXY, which inserts it regardless); TELEPORT_S, IMPATIENCE_S: see there
    files = ",".join(route_files)
    cap = f'\n        <max-num-vehicles value="{max_vehicles}"/>' if max_vehicles >= 0 else ""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<configuration>
    <input>
        <net-file value="{net_rel}"/>
        <route-files value="{files}"/>
    </input>
    <time>
        <begin value="0"/>
        <end value="{end:.0f}"/>
        <step-length value="{STEP_LENGTH}"/>
    </time>
    <processing>
        <collision.action value="warn"/>
        <collision.check-junctions value="true"/>
        <collision.mingap-factor value="0"/>
        <time-to-teleport value="{TELEPORT_S:.0f}"/>
        <time-to-impatience value="{IMPATIENCE_S:.0f}"/>{cap}
    </processing>
    <random_number>
        <seed value="{seed}"/>
    </random_number>
    <report>
        <no-step-log value="true"/>
        <duration-log.disable value="true"/>
        <no-warnings value="true"/>
    </report>
</configuration>
"""


def _ego_routes(edges: tuple[str, ...]) -> str:
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<routes>
    <vType id="ego" vClass="passenger" length="{EGO_LENGTH}" width="{EGO_WIDTH}" color="1,0,0"
           timeToTeleport="-1"/>
    <route id="ego_route" edges="{' '.join(edges)}"/>
</routes>
"""


def _convert_one(
    spec: RouteSpec, routes_file: str, net_path: str, town: str, out_dir: str,
    opts: ConvertOptions,
) -> tuple[str, str, InputError | None]:
    """Convert one route (runs in a worker process). Returns (status, folder name, error)
    with status 'converted', 'reused' or 'failed' (with its error)."""
    name = safe_name(spec.id)
    final = Path(out_dir) / "scenarios" / name
    try:
        net = load_net(Path(net_path))
        source_hash = _source_hash(spec, net.sha256, opts)
        old = final / MANIFEST
        if old.is_file():
            try:  # a damaged old manifest is converted anew
                old_doc = json.loads(old.read_text(encoding="utf-8"))
                if isinstance(old_doc, dict) and old_doc.get("source_hash") == source_hash:
                    read_scenario(final)  # still whole: its files and network are there
                    return "reused", name, None
            except (OSError, ValueError, RecursionError, InputError):
                pass
        pts = [net.to_sumo(w.x, w.y, w.yaw, opts.coords) for w in spec.waypoints]
        try:
            route = plan_route(net, pts, opts.max_snap)
        except MatchError as err:
            place = f"route {spec.id}, waypoint {err.index}"
            fix = (f"move the waypoint onto a road, check {Field('coords')}, or raise {Field('max_snap')}"
                   if err.kind == "far" else
                   "check the waypoint order and that the network connects them")
            raise InputError(routes_file, place, err.detail, fix) from None
        seed = route_seed(opts.seed, spec.id)
        end = opts.warmup + _route_timeout(route.length) + 60.0
        staging = Path(tempfile.mkdtemp(prefix=f".{name}.", dir=final.parent))
        try:
            traffic = make_traffic(
                net.path, net.lane_km, net.edge_km, net.has_sidewalks, staging, seed,
                opts.traffic, end,
            )
            cap = fleet_cap(spec.town or town, net.lane_km, opts.traffic) if traffic.vehicles else -1
            net_rel = os.path.relpath(net.path, final)
            route_files = ["ego.rou.xml"] + [f for f in (traffic.vehicles, traffic.pedestrians) if f]
            (staging / "ego.rou.xml").write_text(_ego_routes(route.edges), encoding="utf-8")
            (staging / "scenario.sumocfg").write_text(
                sumocfg_xml(net_rel, route_files, seed, end, cap), encoding="utf-8")
            manifest = {
                "format": SCENARIO_FORMAT,
                "route_id": spec.id,
                "town": spec.town or town,
                "source": {"file": Path(routes_file).name, "index": spec.index,
                           "coords": opts.coords},
                "net": net_rel,
                "net_sha256": net.sha256,
                "sumocfg": "scenario.sumocfg",
                "seed": seed,
                "step_length": STEP_LENGTH,
                "weather": dict(spec.weather),
                "waypoints": [[round(x, 2), round(y, 2)] for x, y, _ in pts],
                "ego": {
                    "vtype": "ego", "route": "ego_route", "depart": opts.warmup,
                    "length": EGO_LENGTH, "width": EGO_WIDTH,
                    "edges": list(route.edges), "lanes": [list(x) for x in route.lanes],
                    "lane_path": list(route.lane_path),
                    "start": asdict(route.start), "end": asdict(route.end),
                },
                "route": {"length": route.length, "timeout": round(_route_timeout(route.length), 2),
                          "polyline": [list(p) for p in route.polyline],
                          "headings": list(route.headings)},
                "junctions": [asdict(j) for j in route.junctions],
                "lane_changes": [dict(asdict(c), direction=c.direction) for c in route.lane_changes],
                "traffic": {"level": opts.traffic, "vehicles": traffic.vehicles,
                            "pedestrians": traffic.pedestrians,
                            "n_vehicles": traffic.n_vehicles,
                            "n_pedestrians": traffic.n_pedestrians, "begin": 0.0, "end": end,
                            "max_vehicles": cap},
                "source_hash": source_hash,
            }
            (staging / MANIFEST).write_text(dumps_json(manifest), encoding="utf-8")
            replace_dir_atomic(staging, final)
        finally:
            if staging.exists():
                shutil.rmtree(staging, ignore_errors=True)
        return "converted", name, None
    except InputError as err:
        return "failed", name, err
    except Exception as err:  # a simulator tool failed: report it for this route, go on
        why = f"{routes_file}: route {spec.id}: {type(err).__name__}: {err}"
        return "failed", name, InputError.of_line(why)


def convert_routes(routes_file: Path, out_dir: Path, opts: ConvertOptions,
                   refuse_empty: bool = False) -> ConvertReport:
    """Convert every route of ``routes_file`` into ``out_dir``; bad routes are reported in the
    returned report and do not stop the others. File-level problems raise InputError before
    anything is written. With ``refuse_empty``, a run in which no route could be converted
    removes what it wrote into a new (or empty) ``out_dir`` and raises the first route's error."""
    opts.check()
    routes_file = Path(routes_file)
    out_dir = Path(out_dir)
    check_out_dir(out_dir)
    before = OutFolder.before(out_dir)
    specs, parse_errors = read_routes(routes_file)
    net_store = out_dir / "networks"
    # a user's network is read whole (load_net: unsafe XML, not a SUMO network) before anything
    # is copied or written into OUT; only netconvert's output of an OpenDRIVE file lands there
    resolved, net_errors = _resolve_nets(specs, opts, routes_file, net_store)
    net_store.mkdir(parents=True, exist_ok=True)
    (out_dir / "scenarios").mkdir(parents=True, exist_ok=True)
    for stale in (out_dir / "scenarios").glob(".*"):  # staging left by a killed run
        shutil.rmtree(stale, ignore_errors=True)
    placed: dict[Path, Path] = {}
    jobs = []
    for s in specs:
        if s.id in resolved:
            src, name = resolved[s.id]
            if src not in placed:
                placed[src] = _place_net(src, name, net_store)
            jobs.append((s, str(routes_file), str(placed[src]), name, str(out_dir), opts))
    names = [safe_name(s.id) for s in specs]
    clash = {n for n in names if names.count(n) > 1}
    failed: list[tuple[int, InputError]] = list(parse_errors)
    ok_jobs = []
    for job in jobs:
        if safe_name(job[0].id) in clash:
            failed.append((job[0].index, InputError(
                routes_file, f"route {job[0].id}", "route id maps to the same folder name as "
                "another route", "make route ids differ in letters or digits")))
        else:
            ok_jobs.append(job)
    results: dict[str, tuple[str, str, InputError | None]] = {}
    # spawned, not forked: the caller may hold libsumo, torch or Ray threads, which a fork copies
    # in whatever state they are (a forked conversion worker died that way in a full test run)
    with ProcessPoolExecutor(max_workers=min(opts.workers, max(1, len(ok_jobs))),
                             mp_context=spawn_context()) as pool:
        futures = {job[0].id: pool.submit(_convert_one, *job) for job in ok_jobs}
        for rid, fut in futures.items():
            results[rid] = fut.result()
    report = ConvertReport()
    index = []
    for s in specs:
        if s.id in net_errors:
            failed.append((s.index, net_errors[s.id]))
            continue
        if s.id not in results:
            continue
        status, name, err = results[s.id]
        if status == "failed":
            failed.append((s.index, err))
            continue
        (report.converted if status == "converted" else report.reused).append(name)
        index.append({"id": s.id, "town": s.town, "dir": f"scenarios/{name}"})
    report.errors = [err for _, err in sorted(failed, key=lambda f: f[0])]
    if refuse_empty and report.errors and not (report.converted or report.reused):
        before.undo()
        raise report.errors[0]
    write_atomic(out_dir / "index.json", dumps_json({
        "format": "icrsumo-index/1", "routes_file": routes_file.name,
        "scenarios": index, "failures": report.failures,
    }))
    return report
