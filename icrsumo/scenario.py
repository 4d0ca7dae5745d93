"""Scenario manifests: the converted, runnable form of one route (``scenario.json``)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from .fsio import read_json_doc

SCENARIO_FORMAT = "icrsumo-scenario/1"
MANIFEST = "scenario.json"


@dataclass(frozen=True)
class Scenario:
    """One runnable scenario. Paths are absolute; lengths in m, times in s, angles in rad.

    ``ego_edges``: the ego's normal edges in order; ``polyline``: (N, 2) route centre line;
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


def read_scenario(path: Path) -> Scenario:
    """Load a scenario from its folder or its ``scenario.json``."""
    path = Path(path)
    mpath = path / MANIFEST if path.is_dir() else path
    m = read_json_doc(mpath, SCENARIO_FORMAT, "scenario manifest", "run icrsumo convert-routes")
    base = mpath.parent
    ego, st = m["ego"], m["ego"]["start"]
    return Scenario(
        route_id=m["route_id"], town=m["town"], dir=base,
        net=(base / m["net"]).resolve(), sumocfg=(base / m["sumocfg"]).resolve(),
        seed=int(m["seed"]), ego_edges=tuple(ego["edges"]), start_lane=st["lane"],
        start_pos=float(st["pos"]), start=(float(st["x"]), float(st["y"]), float(st["heading"])),
        polyline=tuple((float(x), float(y)) for x, y in m["route"]["polyline"]),
        length=float(m["route"]["length"]), ego_depart=float(ego["depart"]),
        end_time=float(m["traffic"]["end"]), weather=dict(m["weather"]), manifest=m,
    )


def find_scenarios(root: Path) -> list[Path]:
    """Scenario folders below ``root`` in the order of ``index.json`` (else sorted by name)."""
    root = Path(root)
    index = root / "index.json"
    if index.is_file():
        data = json.loads(index.read_text(encoding="utf-8"))
        return [root / s["dir"] for s in data["scenarios"]]
    return sorted(p.parent for p in root.glob(f"**/{MANIFEST}"))
