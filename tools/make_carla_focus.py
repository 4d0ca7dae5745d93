"""Regenerate the bundled ``carla-focus`` split (``routes/carla-focus/``, byte-identical for the
same networks): extra training routes on CARLA's towns that each hold one of the maneuvers the
``carla-train`` split has too few of for the learned agents to drive LangAuto's long routes.

``carla-train`` draws routes at random; a maneuver rare on random routes is rare in its data.
Its 128 routes hold 13 lane changes across two lanes or more and pass a roundabout 10 times,
and the learned agents trained on it fail exactly there (README, *LangAuto: the learned
agents*). This split draws routes the same way (:func:`make_routes.make_split`, the same random
walks and key waypoints) and keeps only the draws that hold

- a lane change across two lanes or more (``lane changes``), or
- a roundabout passage (``roundabout``),

with the start lane chosen, as ``carla-train`` does half of the time, among the lanes from which
the route cannot go on. Maneuver types are targeted, never places: every town with such a
maneuver contributes, and no route equals or contains a LangAuto route's edge sequence (the same
test as ``carla-train``), nor repeats one of ``carla-train``'s.

    python tools/make_carla_focus.py [--out routes/carla-focus]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from make_carla_routes import TOWNS, carla_towns, out_folder, suite_edges, write_suite  # noqa: E402
from make_routes import Split, make_split, summarise  # noqa: E402

from icrsumo.core.types import EgoRoute, RouteSpec  # noqa: E402
from icrsumo.world.networks import RoadNet  # noqa: E402

SEED = 9099
SUITE = "carla-focus"
#: routes per town and kind (lane changes across >= 2 lanes; roundabout passages). Town01, 02, 07
#: and 10HD have no edge with three passenger lanes, none of 20,000 draws in Town03 needed such a
#: change, and only Town03's network has a roundabout.
PER_TOWN = {
    "lanes": {"Town04": 24, "Town05": 12, "Town06": 32},
    "roundabout": {"Town03": 24},
}
SPLIT = Split("focus", 0, 150.0, 700.0, 1)
SUITE_JSON = {
    "format": "icrsumo-suite/1", "coords": "carla",
    "source": "icrsumo's own training routes on CARLA's towns that each hold a multi-lane change "
              "or a roundabout, drawn by tools/make_carla_focus.py; disjoint from LangAuto's "
              "routes (routes/langauto/)",
    "towns": sorted({t for per in PER_TOWN.values() for t in per}),
}
README = """# carla-focus: icrsumo's maneuver-focused training routes on CARLA's towns (generated)

`carla-focus.xml` is **not** part of LangAuto: icrsumo drew these routes itself
(`python tools/make_carla_focus.py`, deterministic, byte-identical on every run) to add training
data for two maneuvers that random routes (`carla-train`) hold too rarely: lane changes across
two lanes or more, and roundabouts. Leaderboard route format in CARLA coordinates
(`suite.json`: `"coords": "carla"`). Route ids `carla_focus_<lanes|roundabout>_NNN`.

No route has the edge sequence of a LangAuto route (`routes/langauto/`, the evaluation
routes) or contains one as a contiguous part (tested). Use these routes for `icrsumo collect`,
never for evaluation.
"""


def multi_lane_change(net: RoadNet, route: EgoRoute) -> bool:
    """The route needs a lane change across two lanes or more."""
    return any(c.lanes >= 2 for c in route.lane_changes)


def roundabout(net: RoadNet, route: EgoRoute) -> bool:
    """The route enters a roundabout."""
    return any(net.enters_roundabout(j.from_edge, j.to_edge) for j in route.junctions)


KINDS = {"lanes": multi_lane_change, "roundabout": roundabout}


def main() -> None:
    out = out_folder(__doc__, SUITE)
    towns, avoid = carla_towns()
    used: set[tuple[str, ...]] = set(avoid)
    used.update(suite_edges(towns, ("carla-train",)))
    rng = np.random.default_rng(SEED)
    specs: list[RouteSpec] = []
    routes: list[EgoRoute] = []
    for kind, per in PER_TOWN.items():
        ts = {t: towns[t] for t in TOWNS if t in per}
        got, drawn = make_split(SPLIT, ts, per, rng, f"carla_focus_{kind}", used, coords="carla",
                                avoid=avoid, strict=False, accept=KINDS[kind], attempts=20_000)
        print(summarise(f"{SUITE} {kind}", drawn))
        specs += got
        routes += drawn
    print(summarise(SUITE, routes))
    write_suite(out, SUITE, specs, SUITE_JSON, README)


if __name__ == "__main__":
    main()
