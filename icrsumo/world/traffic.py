"""Background traffic (vehicles and pedestrians) from SUMO's randomTrips.py with a fixed seed.

randomTrips seeds Python's global ``random`` itself; we run it only inside worker processes
(see :mod:`icrsumo.world.convert`) so that the caller's interpreter keeps no changed global state.
"""

from __future__ import annotations

import contextlib
import io
import sys
from dataclasses import dataclass
from pathlib import Path

from icrsumo.core.fsio import strip_header_comments
from icrsumo.core.resources import sumo_home

#: vehicles inserted per hour per km of lane, and pedestrians per hour per km of edge, by level
TRAFFIC_LEVELS: dict[str, tuple[float, float]] = {
    "none": (0.0, 0.0),
    "light": (75.0, 60.0),
    "normal": (150.0, 120.0),
    "dense": (300.0, 240.0),
}

#: background vehicles CARLA Leaderboard 1.0 keeps on each town at once
#: (``leaderboard/scenarios/route_scenario.py``, ``_initialize_actors``: ``town_amount``; Town10HD's
#: number from LMDrive's copy of that file, whose key names the map as CARLA loads it)
LEADERBOARD_FLEET: dict[str, int] = {
    "Town01": 120, "Town02": 100, "Town03": 120, "Town04": 200, "Town05": 120, "Town06": 150,
    "Town07": 110, "Town10HD": 120,
}
#: vehicles at once per km of passenger lane on icrsumo's own towns at ``normal``: above what
#: their demand keeps there when nothing jams (2.5-6.5 per km measured by
#: ``tools/traffic_jams.py``), so the cap only ever stops a jam from growing
FLEET_PER_LANE_KM = 10.0
#: the fleet cap of a level, as a multiple of the ``normal`` one
FLEET_FACTOR: dict[str, float] = {"none": 0.0, "light": 0.5, "normal": 1.0, "dense": 2.0}


def fleet_cap(town: str, lane_km: float, level: str) -> int:
    """The most background vehicles in the network at once (SUMO's ``max-num-vehicles``): the
    leaderboard's fleet on CARLA's towns, :data:`FLEET_PER_LANE_KM` per km of lane elsewhere,
    times the level's :data:`FLEET_FACTOR`. Insertions wait while the cap is reached, so the
    demand of :data:`TRAFFIC_LEVELS` can never pile up into a gridlock (FINDINGS-2, class F)."""
    base = LEADERBOARD_FLEET.get(town, FLEET_PER_LANE_KM * lane_km)
    return int(round(base * FLEET_FACTOR[level]))


@dataclass(frozen=True)
class TrafficFiles:
    """Route files written for one scenario (names relative to the scenario folder)."""

    vehicles: str | None
    pedestrians: str | None
    n_vehicles: int
    n_pedestrians: int


def _random_trips(args: list[str]) -> None:
    """Call randomTrips.main in-process (stdout silenced); a SystemExit becomes RuntimeError."""
    tools = str(sumo_home() / "tools")
    if tools not in sys.path:
        sys.path.append(tools)
    import randomTrips  # SUMO's tool, shipped in the eclipse-sumo wheel

    sink = io.StringIO()
    try:
        with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
            randomTrips.main(randomTrips.get_options(args))
    except SystemExit as exc:
        if exc.code not in (None, 0):
            raise RuntimeError(f"randomTrips failed: {sink.getvalue().strip()[-300:]}") from None


def make_traffic(
    net_path: Path, net_lane_km: float, net_edge_km: float, sidewalks: bool, out_dir: Path,
    seed: int, level: str, end: float,
) -> TrafficFiles:
    """Write ``vehicles.rou.xml`` (and ``pedestrians.rou.xml`` when the net has sidewalks) into
    ``out_dir``: trips inserted evenly from t=0 to ``end`` (s), routed by duarouter.

    ``net_lane_km``/``net_edge_km`` are the network's passenger-lane and edge lengths (km);
    the insertion rate is the level's density times that length.
    """
    veh_density, ped_density = TRAFFIC_LEVELS[level]
    files: dict[str, str | None] = {"vehicles": None, "pedestrians": None}
    counts = {"vehicles": 0, "pedestrians": 0}
    jobs = []
    if veh_density > 0:
        jobs.append(("vehicles", veh_density * net_lane_km, seed, [
            "--vehicle-class", "passenger", "--prefix", "veh", "--min-distance", "100",
            "--trip-attributes", 'departLane="best" departSpeed="max"',
        ]))
    if ped_density > 0 and sidewalks:
        jobs.append(("pedestrians", ped_density * net_edge_km, seed + 1, [
            "--pedestrians", "--prefix", "ped", "--max-distance", "500",
        ]))
    for name, per_hour, job_seed, extra in jobs:
        trips = out_dir / f".{name}.trips.xml"
        rou = out_dir / f"{name}.rou.xml"
        period = 3600.0 / per_hour
        _random_trips([
            "--net-file", str(net_path), "--output-trip-file", str(trips), "--route-file", str(rou),
            "--seed", str(job_seed), "--begin", "0", "--end", f"{end:.0f}",
            "--period", f"{period:.4f}", *extra,
        ])
        trips.unlink(missing_ok=True)
        for aux in out_dir.glob(f"{name}.rou.alt.xml"):
            aux.unlink()
        text = strip_header_comments(rou.read_text(encoding="utf-8"))
        rou.write_text(text, encoding="utf-8")
        tag = "<vehicle " if name == "vehicles" else "<person "
        counts[name] = text.count(tag)
        files[name] = rou.name
    return TrafficFiles(files["vehicles"], files["pedestrians"], counts["vehicles"],
                        counts["pedestrians"])
