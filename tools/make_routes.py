"""Regenerate the bundled route suites in ``routes/`` (byte-identical for the same networks).

Splits mirror LangAuto: ``tiny`` (16 routes, under 150 m), ``short`` (16 routes, 150-500 m),
``long`` (32 routes, 500 m and more, mean about 600 m), spread over the bundled towns, plus a
larger ``train`` split drawn with a different seed and sharing no route (edge sequence) with
the evaluation splits.

A route is a random walk over the town's passenger-car graph that never revisits an edge and
takes at least the split's number of junction maneuvers (junctions where more than one way on
is possible). Its key waypoints are few, as in LangAuto: start and end, plus a waypoint on any
edge where the leaderboard's shortest-path planner (our converter) would otherwise take
another way. Every written route is checked by converting its waypoints back with
``icrsumo.world.routing.plan_route`` and comparing the edge sequence.

Waypoints are in SUMO coordinates (the bundled nets have netOffset 0), yaw in degrees
counter-clockwise from +x. ``tools/make_carla_routes.py`` reuses these functions to draw the
``carla-train`` split on CARLA's towns, with waypoints in CARLA coordinates.

    python tools/make_routes.py [--out routes]
"""

from __future__ import annotations

import argparse
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from icrsumo.core.fsio import write_atomic
from icrsumo.core.resources import bundled_towns
from icrsumo.core.types import EgoRoute, RouteSpec, Waypoint
from icrsumo.world.convert import ConvertOptions
from icrsumo.world.networks import RoadNet, load_net
from icrsumo.world.routes import format_routes
from icrsumo.world.routing import MatchError, plan_route

EVAL_SEED = 20260
#: waypoints are checked with the converter's default snapping radius (m)
SNAP = ConvertOptions().max_snap
TRAIN_SEED = 777
#: m/s below which a passenger lane is no driving lane for a route's waypoints
MIN_LANE_SPEED = 2.0


@dataclass(frozen=True)
class Split:
    """Route count, length bounds (m) and minimum junction maneuvers of a split; ``mean_len``
    (m): target lengths drawn around it (standard deviation a tenth of it) instead of uniformly
    between the bounds."""

    name: str
    count: int
    min_len: float
    max_len: float
    min_turns: int
    skip_towns: tuple[str, ...] = ()
    mean_len: float = 0.0


#: icr_rural's roads run 360-450 m between junctions, so a 500-760 m route there passes at most
#: two junctions: long routes (three maneuvers or more) are drawn in the other towns.
EVAL_SPLITS = (
    Split("tiny", 16, 60.0, 149.0, 1),
    Split("short", 16, 150.0, 500.0, 1),
    Split("long", 32, 500.0, 760.0, 3, skip_towns=("icr_rural",), mean_len=600.0),
)
#: the train split mixes all three length classes, 48 routes per town
TRAIN_PER_TOWN = {"tiny": 16, "short": 16, "long": 16}

#: CARLA weather presets (a subset), attributes as the leaderboard writes them
WEATHERS = (
    ("ClearNoon", 5.0, 0.0, 0.0, 10.0, 45.0),
    ("CloudyNoon", 60.0, 0.0, 0.0, 10.0, 45.0),
    ("WetNoon", 5.0, 0.0, 50.0, 10.0, 45.0),
    ("SoftRainNoon", 20.0, 30.0, 50.0, 30.0, 45.0),
    ("ClearSunset", 5.0, 0.0, 0.0, 10.0, 15.0),
    ("CloudySunset", 60.0, 0.0, 0.0, 10.0, 15.0),
    ("WetCloudyNoon", 60.0, 0.0, 50.0, 10.0, 45.0),
    ("MidRainSunset", 60.0, 60.0, 60.0, 60.0, 15.0),
)


def _weather(rng: np.random.Generator) -> tuple[tuple[str, str], ...]:
    wid, cloud, rain, deposits, wind, sun_alt = WEATHERS[int(rng.integers(len(WEATHERS)))]
    vals = {
        "cloudiness": cloud, "fog_density": 3.0, "fog_distance": 0.75, "fog_falloff": 0.1,
        "id": wid, "precipitation": rain, "precipitation_deposits": deposits,
        "sun_altitude_angle": sun_alt, "sun_azimuth_angle": -1.0, "wetness": 0.0,
        "wind_intensity": wind,
    }
    return tuple((k, v if isinstance(v, str) else f"{v:.1f}") for k, v in vals.items())


def onward_edges(net: RoadNet, edge: str) -> list[str]:
    """Successor edges reachable without a U-turn."""
    return [s for s in net.successors.get(edge, ())
            if any(c.direction != "t" for c in net.connections[(edge, s)])]


def _pick(net: RoadNet, rng: np.random.Generator, edges: list[str]) -> str:
    """One of ``edges``, weighted by speed limit squared, so that walks favour main roads and,
    in the highway town, the highway and its ramps over the local streets."""
    w = np.array([net.edge_speed[e] ** 2 for e in edges])
    return edges[int(rng.choice(len(edges), p=w / w.sum()))]


def random_walk(net: RoadNet, rng: np.random.Generator, split: Split):
    """A random route for ``split`` (start lane, start pos, edges, end pos), or None where the
    walk reaches a dead end: edges drawn by speed limit squared, no U-turn, no edge twice."""
    edges_all = sorted(e for e in net.passenger_lanes if net.edge_length[e] >= 25.0)
    start = _pick(net, rng, edges_all)
    length = float(rng.uniform(split.min_len, split.max_len))
    if split.mean_len:  # pull long routes towards their mean
        length = float(np.clip(rng.normal(split.mean_len, 0.1 * split.mean_len),
                               split.min_len + 5, split.max_len - 5))
    first_len = net.edge_length[start]
    rest = float(rng.uniform(min(15.0, first_len - 5), min(first_len - 5, 0.6 * length)))
    pos = first_len - rest
    edges, total, seen = [start], rest, {start}
    while True:
        onward = [e for e in onward_edges(net, edges[-1]) if e not in seen]
        if not onward:
            return None
        nxt = _pick(net, rng, onward)
        total += net.via_length(edges[-1], nxt)
        seen.add(nxt)
        edges.append(nxt)
        elen = net.edge_length[nxt]
        if total + elen - 5.0 >= length:
            end_pos = float(np.clip(length - total, 5.0, elen - 5.0)) if elen > 10 else elen / 2
            return _start_lane(net, rng, edges), pos, edges, end_pos
        total += elen


def _driving_lanes(net: RoadNet, edge: str) -> tuple[int, ...]:
    """The passenger lanes of ``edge`` that are driving lanes: not slower than
    :data:`MIN_LANE_SPEED` (CARLA's parking lanes come out of netconvert at 1.39 m/s)."""
    lanes = net.passenger_lanes[edge]
    fast = tuple(i for i in lanes if net.sumolib_net.getLane(f"{edge}_{i}").getSpeed() >= MIN_LANE_SPEED)
    return fast or lanes


def _start_lane(net: RoadNet, rng: np.random.Generator, edges: list[str]) -> int:
    """Start lane: on multi-lane roads, half of the time one from which the route cannot go on,
    so that the suite holds lane changes."""
    lanes = _driving_lanes(net, edges[0])
    onward = {c.from_lane for c in net.connections[(edges[0], edges[1])]}
    off = [ln for ln in lanes if ln not in onward]
    pool = off if off and rng.random() < 0.5 else lanes
    return pool[int(rng.integers(len(pool)))]


def _waypoint(net: RoadNet, lane: str, pos: float) -> tuple[float, float, float]:
    x, y, h = net.lane_pose(lane, pos)
    return x, y, h


def _lane_on(net: RoadNet, edge: str, prefer: int) -> str:
    lanes = _driving_lanes(net, edge)
    return f"{edge}_{prefer if prefer in lanes else lanes[0]}"


def _pin_waypoints(net: RoadNet, lane: str, pos: float, edges: list[str], end_pos: float):
    """Fewest key waypoints whose shortest-path plan is exactly ``edges``: (points, route)."""
    pts = [_waypoint(net, lane, pos), _waypoint(net, _lane_on(net, edges[-1], 0), end_pos)]
    pinned: list[int] = []  # edge indices with a mid-edge waypoint, ascending
    for _ in range(len(edges)):
        try:
            route = plan_route(net, pts, radius=SNAP)
        except MatchError:
            return None
        if list(route.edges) == edges:
            return pts, route
        got = list(route.edges)
        k = next((i for i, (a, b) in enumerate(zip(got, edges)) if a != b), min(len(got), len(edges)))
        k = min(max(k, 1), len(edges) - 2)
        if k in pinned:
            return None
        pinned.append(k)
        pinned.sort()
        mids = [_waypoint(net, _lane_on(net, edges[i], 0), net.edge_length[edges[i]] / 2)
                for i in pinned]
        pts = [pts[0], *mids, pts[-1]]
    return None


def count_turns(route: EgoRoute) -> int:
    """How many of the route's junction passes are a choice (a turn among several exits)."""
    return sum(1 for j in route.junctions if j.choice)


def file_waypoints(net: RoadNet, pts, coords: str) -> tuple[Waypoint, ...]:
    """SUMO poses (x, y, heading) -> waypoints as written in a route file of frame ``coords``
    (``sumo`` or ``carla``), rounded to the file's 2 decimals."""
    out = []
    for x, y, h in pts:
        fx, fy, yaw = net.to_file_coords(x, y, h, coords)
        out.append(Waypoint(x=round(fx, 2), y=round(fy, 2), yaw=round(yaw, 2)))
    return tuple(out)


def replan(net: RoadNet, waypoints, coords: str) -> tuple[str, ...] | None:
    """The edge sequence ``convert-routes --coords COORDS`` plans through a route file's
    waypoints (None: they do not match the network)."""
    pts = [net.to_sumo(w.x, w.y, w.yaw, coords) for w in waypoints]
    try:
        return plan_route(net, pts, radius=SNAP).edges
    except MatchError:
        return None


def contains(edges: tuple[str, ...], part: tuple[str, ...]) -> bool:
    """Whether ``part`` is a contiguous run of ``edges``."""
    n = len(part)
    return any(edges[i:i + n] == part for i in range(len(edges) - n + 1))


def make_split(
    split: Split, towns: dict[str, RoadNet], per_town: dict[str, int], rng: np.random.Generator,
    prefix: str, forbidden: set[tuple[str, ...]], *, coords: str = "sumo",
    avoid: tuple[tuple[str, ...], ...] = (), strict: bool = True,
    accept: Callable[[RoadNet, EgoRoute], bool] | None = None, attempts: int = 4000,
    walk: Callable[[RoadNet, np.random.Generator, Split], tuple | None] | None = None,
) -> tuple[list[RouteSpec], list[EgoRoute]]:
    """Draw ``per_town[town]`` routes of ``split`` in each town (in town order), waypoints in
    frame ``coords``. Draws whose edge sequence is in ``forbidden`` or holds one of ``avoid`` as
    a contiguous run, or that ``accept`` (if given) turns down, are rejected. A town that yields
    fewer routes in ``attempts`` draws stops the tool (``strict``) or keeps what it drew (a note
    is printed). ``walk`` draws the edge sequences (default: random walks that never revisit
    an edge)."""
    specs: list[RouteSpec] = []
    routes: list[EgoRoute] = []
    for town, net in towns.items():
        made = 0
        for _attempt in range(attempts):
            if made == per_town.get(town, 0):
                break
            drawn = (walk or random_walk)(net, rng, split)
            if drawn is None:
                continue
            lane, pos, edges, end_pos = drawn
            pinned = _pin_waypoints(net, f"{edges[0]}_{lane}", pos, edges, end_pos)
            if pinned is None:
                continue
            pts, route = pinned
            if not (split.min_len <= route.length <= split.max_len) or count_turns(route) < split.min_turns:
                continue
            if route.edges in forbidden or any(contains(route.edges, p) for p in avoid):
                continue
            if accept is not None and not accept(net, route):
                continue
            wps = file_waypoints(net, pts, coords)
            if replan(net, wps, coords) != route.edges:  # the written file must convert back
                continue
            forbidden.add(route.edges)
            specs.append(RouteSpec(id=f"{prefix}_{len(specs):03d}", town=town, waypoints=wps,
                                   weather=_weather(rng)))
            routes.append(route)
            made += 1
        if made < per_town.get(town, 0):
            if strict:
                raise SystemExit(f"{town}: could not draw {per_town[town]} {split.name} routes")
            print(f"note: {town}: {made} of {per_town[town]} {split.name} routes", flush=True)
    return specs, routes


def _spread(count: int, towns: list[str], offset: int) -> dict[str, int]:
    """``count`` routes over ``towns`` as evenly as possible, extras rotating by ``offset``."""
    base, extra = divmod(count, len(towns))
    return {t: base + (1 if (i - offset) % len(towns) < extra else 0) for i, t in enumerate(towns)}


def summarise(name: str, routes: list[EgoRoute]) -> str:
    dirs = Counter(j.direction for r in routes for j in r.junctions if j.choice)
    lengths = [r.length for r in routes]
    changes = sum(len(r.lane_changes) for r in routes)
    return (f"{name}: {len(routes)} routes, length {min(lengths):.0f}-{max(lengths):.0f} m "
            f"(mean {np.mean(lengths):.0f}), maneuvers {dict(sorted(dirs.items()))}, "
            f"lane changes {changes}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent.parent / "routes")
    args = ap.parse_args()
    # icrsumo's own towns (networks/), not the bundled CARLA towns (networks/carla/)
    towns = {name: load_net(path) for name, path in bundled_towns().items() if path.parent.name == "networks"}
    names = list(towns)
    used: set[tuple[str, ...]] = set()
    rng = np.random.default_rng(EVAL_SEED)
    outputs = {}
    for i, split in enumerate(EVAL_SPLITS):
        split_towns = [t for t in names if t not in split.skip_towns]
        specs, routes = make_split(split, towns, _spread(split.count, split_towns, 2 * i), rng,
                                   split.name, used)
        outputs[split.name] = specs
        print(summarise(split.name, routes))
    rng = np.random.default_rng(TRAIN_SEED)
    train_specs: list[RouteSpec] = []
    train_routes: list[EgoRoute] = []
    for split in EVAL_SPLITS:
        per = {t: TRAIN_PER_TOWN[split.name] for t in names if t not in split.skip_towns}
        specs, routes = make_split(split, towns, per, rng, f"train_{split.name}", used)
        train_specs += specs
        train_routes += routes
    outputs["train"] = train_specs
    print(summarise("train", train_routes))
    for name, specs in outputs.items():
        write_atomic(args.out / f"{name}.xml", format_routes(specs))


if __name__ == "__main__":
    main()
