"""Regenerate the bundled ``carla-train`` split (``routes/carla-train/``, byte-identical for the
same networks): training routes on CARLA's eight towns that never drive a LangAuto route.

The routes are drawn as ``tools/make_routes.py`` draws icrsumo's own splits (its functions, not
a copy): random walks over a town's passenger-car graph that never revisit an edge, at least
one junction maneuver, few key waypoints (start, end, and one on any edge where the
shortest-path planner would otherwise go another way). The mix of lengths follows LangAuto
(per town 2 tiny, 2 short, 4 long routes there): per town 4 tiny (60-149 m), 4 short
(150-500 m) and 8 long routes (500-1,200 m, about 700 m on average, at least two maneuvers);
a town too small to hold them all keeps fewer (a note is printed).

Waypoints are written in CARLA coordinates, the frame of LangAuto's route files
(``suite.json``: ``{"coords": "carla"}``), and every route is checked by the round trip
``convert-routes`` makes: the written (rounded) waypoints, mapped to SUMO's frame with the
town's netOffset and planned with :func:`icrsumo.world.routing.plan_route`, give the drawn edge
sequence.

Disjoint from LangAuto: LangAuto's 64 routes (``routes/langauto/``) are planned the same way,
and a draw is rejected when its edge sequence equals one of theirs or holds one as a contiguous
run (training never drives a complete evaluation route).

    python tools/make_carla_routes.py [--out routes/carla-train]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from make_routes import Split, make_split, replan, summarise  # noqa: E402

from icrsumo.core.fsio import dumps_json, write_atomic  # noqa: E402
from icrsumo.core.resources import bundled_suites, bundled_towns  # noqa: E402
from icrsumo.core.types import EgoRoute, RouteSpec  # noqa: E402
from icrsumo.world.networks import RoadNet, load_net  # noqa: E402
from icrsumo.world.routes import format_routes, read_routes  # noqa: E402

SEED = 8088
SUITE = "carla-train"
TOWNS = ("Town01", "Town02", "Town03", "Town04", "Town05", "Town06", "Town07", "Town10HD")
LANGAUTO = ("langauto-tiny", "langauto-short", "langauto-long")
#: split totals over the eight towns: 4 tiny, 4 short, 8 long per town
SPLITS = (
    Split("tiny", 32, 60.0, 149.0, 1),
    Split("short", 32, 150.0, 500.0, 1),
    Split("long", 64, 500.0, 1200.0, 2, mean_len=700.0),
)
SUITE_JSON = {
    "format": "icrsumo-suite/1", "coords": "carla",
    "source": "icrsumo's own training routes on CARLA's towns, drawn by tools/make_carla_routes.py; "
              "disjoint from LangAuto's routes (routes/langauto/)",
    "towns": list(TOWNS),
}
README = """# carla-train: icrsumo's training routes on CARLA's towns (generated)

`carla-train.xml` is **not** part of LangAuto: icrsumo drew these routes itself
(`python tools/make_carla_routes.py`, deterministic, byte-identical on every run) to collect
training data on CARLA's eight towns (`networks/carla/`). Leaderboard route format in CARLA
coordinates, like LangAuto's files (`suite.json`: `"coords": "carla"`, so `--suite carla-train`
needs no other flag). Route ids `carla_train_<tiny|short|long>_NNN`.

No route has the edge sequence of a LangAuto route (`routes/langauto/`, the evaluation
routes) or contains one as a contiguous part (tested), so training never drives a complete
evaluation route. Use these routes for `icrsumo collect`, never for evaluation.
"""


def suite_edges(towns: dict[str, RoadNet], suites: tuple[str, ...]) -> tuple[tuple[str, ...], ...]:
    """The edge sequences of the bundled ``suites``' routes, as ``convert-routes`` plans them."""
    out = []
    for suite in suites:
        specs, errors = read_routes(bundled_suites()[suite])
        assert not errors, errors
        for s in specs:
            edges = replan(towns[s.town], s.waypoints, "carla")
            if edges is None:
                raise SystemExit(f"{suite}: route {s.id} does not match {s.town}")
            out.append(edges)
    return tuple(out)


def langauto_edges(towns: dict[str, RoadNet]) -> tuple[tuple[str, ...], ...]:
    """The edge sequences of LangAuto's 64 routes, as ``convert-routes`` plans them."""
    return suite_edges(towns, LANGAUTO)


def per_town_table(specs: list[RouteSpec], routes: list[EgoRoute]) -> str:
    """Route count and length range (m) per town and length class."""
    lens: dict[tuple[str, str], list[float]] = {}
    for s, r in zip(specs, routes):
        lens.setdefault((s.town, s.id.split("_")[2]), []).append(r.length)
    lines = []
    for town in TOWNS:
        cells = []
        for cls in (sp.name for sp in SPLITS):
            ls = lens.get((town, cls), [])
            cells.append(f"{cls} {len(ls)}" + (f" ({min(ls):.0f}-{max(ls):.0f} m)" if ls else ""))
        lines.append(f"  {town}: " + ", ".join(cells))
    return "\n".join(lines)


def out_folder(doc: str, suite: str) -> Path:
    """The ``--out`` folder of a route tool (default ``routes/<suite>``)."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--out", type=Path,
                    default=Path(__file__).resolve().parent.parent / "routes" / suite)
    return ap.parse_args().out


def carla_towns() -> tuple[dict[str, RoadNet], tuple[tuple[str, ...], ...]]:
    """CARLA's eight towns and the edge sequences of LangAuto's routes on them."""
    towns = {t: load_net(bundled_towns()[t]) for t in TOWNS}
    return towns, langauto_edges(towns)


def write_suite(out: Path, suite: str, specs: list[RouteSpec], meta: dict, readme: str) -> None:
    """A bundled suite folder: ``<suite>.xml``, ``suite.json`` and ``README.md``."""
    write_atomic(out / f"{suite}.xml", format_routes(specs))
    write_atomic(out / "suite.json", dumps_json(meta))
    write_atomic(out / "README.md", readme)


def main() -> None:
    out = out_folder(__doc__, SUITE)
    towns, avoid = carla_towns()
    used: set[tuple[str, ...]] = set(avoid)
    rng = np.random.default_rng(SEED)
    specs: list[RouteSpec] = []
    routes: list[EgoRoute] = []
    for split in SPLITS:
        per = dict.fromkeys(TOWNS, split.count // len(TOWNS))
        got, drawn = make_split(split, towns, per, rng, f"carla_train_{split.name}", used,
                                coords="carla", avoid=avoid, strict=False)
        print(summarise(f"{SUITE} {split.name}", drawn))
        specs += got
        routes += drawn
    print(summarise(SUITE, routes))
    print(per_town_table(specs, routes))
    write_suite(out, SUITE, specs, SUITE_JSON, README)


if __name__ == "__main__":
    main()
