"""Regenerate the bundled ``carla-fidelity`` suite (``routes/carla-fidelity/``, byte-identical
for the same networks): routes on CARLA's eight towns, drawn at random and never tuned on, to
measure whether the route-oracle and the simulation drive cleanly on routes nobody fitted them
to (README, *Fidelity on routes nobody tuned on*).

The routes are drawn as the training splits draw theirs (:func:`make_routes.make_split`: random
walks over a town's passenger-car graph, few key waypoints, every written file converting back
to the drawn edge sequence), 300 m to 2 km long, in five kinds that real leaderboard route
files hold (``../shared/carla/FINDINGS-2.md``):

- ``mixed``: any random walk with two junction maneuvers or more;
- ``revisit``: a walk that goes around a block (or any loop of up to seven roads) and comes
  back onto a road it has already driven, then leaves it the way it did not take before;
- ``junctions``: a walk with at least :data:`DENSE_PER_KM` junction maneuvers per km;
- ``lanes``: a walk with a lane change across two lanes or more;
- ``highway``: a walk that ends on a road of :data:`HIGHWAY_LANES` lanes or more (CARLA's towns
  sign every road 13.9 m/s after conversion, so lanes, not speed, tell a highway).

A town that cannot hold a kind (no three-lane road, no highway) draws ``mixed`` routes instead,
so every town keeps :data:`PER_TOWN` routes. No route equals or contains a LangAuto route's edge
sequence, nor repeats a route of the training splits (``carla-train``, ``carla-focus``).

    python tools/make_carla_fidelity.py [--out routes/carla-fidelity]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from make_carla_routes import TOWNS, carla_towns, out_folder, suite_edges, write_suite  # noqa: E402
from make_routes import Split, count_turns, make_split, onward_edges, random_walk, summarise  # noqa: E402

from icrsumo.core.types import EgoRoute, RouteSpec  # noqa: E402
from icrsumo.world.networks import RoadNet  # noqa: E402

SEED = 31337
SUITE = "carla-fidelity"
#: routes per town
PER_TOWN = 13
#: routes per town and kind (the rest of PER_TOWN are ``mixed``)
KIND_COUNTS = {"revisit": 2, "junctions": 2, "lanes": 4, "highway": 3}
SPLIT = Split("fidelity", 0, 300.0, 2000.0, 2)
#: junction maneuvers per km of a ``junctions`` route
DENSE_PER_KM = 7.0
#: driving lanes of a road that counts as a highway
HIGHWAY_LANES = 3
#: the longest loop a ``revisit`` route drives before it comes back (roads)
MAX_LOOP = 7
SUITE_JSON = {
    "format": "icrsumo-suite/1", "coords": "carla",
    "source": "icrsumo's own evaluation routes on CARLA's towns for the fidelity of the simulation "
              "and the route-oracle, drawn at random by tools/make_carla_fidelity.py and never tuned "
              "on; disjoint from LangAuto's routes (routes/langauto/) and the training splits",
    "towns": list(TOWNS),
}
README = """# carla-fidelity: routes nobody tuned on (generated)

`carla-fidelity.xml` is **not** part of LangAuto: icrsumo drew these routes itself
(`python tools/make_carla_fidelity.py`, deterministic, byte-identical on every run) to check that
the simulation and the privileged route-oracle drive cleanly on routes that nobody fitted them
to. 13 routes on each of CARLA's eight towns, 300 m to 2 km, in five kinds: `mixed` (random),
`revisit` (the route comes back onto a road it has driven and leaves it another way),
`junctions` (dense junctions), `lanes` (a lane change across two lanes or more) and `highway`
(ending on a highway). Leaderboard route format in CARLA coordinates (`suite.json`:
`"coords": "carla"`). Route ids `carla_fidelity_<kind>_NNN`.

No route has the edge sequence of a LangAuto route or of a training route, or contains a LangAuto
route as a contiguous part. Do not tune anything on these routes: they are the check that tuning
on LangAuto's routes generalises.
"""


def revisit_walk(net: RoadNet, rng: np.random.Generator, split: Split):
    """A random walk (as :func:`make_routes.random_walk`) with a loop spliced in: at one of its
    edges the route first drives a loop of up to :data:`MAX_LOOP` roads that ends back on that
    edge, then leaves it as the walk did. None when the walk has no such loop."""
    drawn = random_walk(net, rng, split)
    if drawn is None:
        return None
    lane, pos, edges, end_pos = drawn
    for i in rng.permutation(len(edges) - 1):
        i = int(i)
        loop = _loop(net, rng, edges[i], avoid=edges[i + 1])
        if loop:
            return lane, pos, [*edges[:i + 1], *loop, edges[i], *edges[i + 1:]], end_pos
    return None


def _loop(net: RoadNet, rng: np.random.Generator, edge: str, avoid: str) -> list[str] | None:
    """Roads r1 .. rk (k >= 2) with ``edge`` -> r1 -> ... -> rk -> ``edge``, r1 != ``avoid``,
    no road twice: the shortest such loop by a breadth-first search whose ties are broken at
    random; None if there is none within :data:`MAX_LOOP` roads."""
    firsts = [n for n in onward_edges(net, edge) if n != avoid]
    parent: dict[str, str | None] = {}
    frontier = []
    for j in rng.permutation(len(firsts)):
        parent[firsts[int(j)]] = None
        frontier.append(firsts[int(j)])
    for _depth in range(MAX_LOOP):
        nxt_frontier = []
        for e in frontier:
            onward = onward_edges(net, e)
            for j in rng.permutation(len(onward)):
                n = onward[int(j)]
                if n == edge and parent[e] is not None:
                    loop = [e]
                    while parent[loop[-1]] is not None:
                        loop.append(parent[loop[-1]])
                    return loop[::-1]
                if n not in parent and n != edge:
                    parent[n] = e
                    nxt_frontier.append(n)
        frontier = nxt_frontier
    return None


def revisits(net: RoadNet, route: EgoRoute) -> bool:
    """The route drives one road twice."""
    return len(set(route.edges)) < len(route.edges)


def dense_junctions(net: RoadNet, route: EgoRoute) -> bool:
    return count_turns(route) >= DENSE_PER_KM * route.length / 1000.0


def multi_lane_change(net: RoadNet, route: EgoRoute) -> bool:
    return any(c.lanes >= 2 for c in route.lane_changes)


def ends_on_highway(net: RoadNet, route: EgoRoute) -> bool:
    return len(net.passenger_lanes[route.edges[-1]]) >= HIGHWAY_LANES


KINDS = {"revisit": revisits, "junctions": dense_junctions, "lanes": multi_lane_change,
         "highway": ends_on_highway}


def can_hold(net: RoadNet, kind: str) -> bool:
    """Whether a town can hold routes of ``kind`` at all (a three-lane road for ``lanes`` and
    ``highway``): towns that cannot are not searched."""
    if kind in ("lanes", "highway"):
        return any(len(lanes) >= HIGHWAY_LANES for lanes in net.passenger_lanes.values())
    return True


def main() -> None:
    out = out_folder(__doc__, SUITE)
    towns, avoid = carla_towns()
    used: set[tuple[str, ...]] = set(avoid)
    used.update(suite_edges(towns, ("carla-train", "carla-focus")))
    rng = np.random.default_rng(SEED)
    specs: list[RouteSpec] = []
    routes: list[EgoRoute] = []
    mixed = {t: PER_TOWN for t in TOWNS}
    for kind, count in KIND_COUNTS.items():
        per = {t: count if can_hold(towns[t], kind) else 0 for t in TOWNS}
        got, drawn = make_split(SPLIT, dict(towns), per, rng,
                                f"{SUITE.replace('-', '_')}_{kind}", used, coords="carla", avoid=avoid,
                                strict=False, accept=KINDS[kind], attempts=1500,
                                walk=revisit_walk if kind == "revisit" else None)
        for s in got:
            mixed[s.town] -= 1
        print(summarise(f"{SUITE} {kind}", drawn), flush=True)
        specs += got
        routes += drawn
    got, drawn = make_split(SPLIT, dict(towns), mixed, rng, f"{SUITE.replace('-', '_')}_mixed", used,
                            coords="carla", avoid=avoid, strict=True)
    print(summarise(f"{SUITE} mixed", drawn))
    specs += got
    routes += drawn
    print(summarise(SUITE, routes))
    write_suite(out, SUITE, specs, SUITE_JSON, README)


if __name__ == "__main__":
    main()
