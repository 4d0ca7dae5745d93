"""The bundled towns and route suites: contents, regeneration, conversion, libsumo insertion."""

from __future__ import annotations

import filecmp
import math
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

from icrsumo.core.resources import bundled_suites, bundled_towns
from icrsumo.world.convert import ConvertOptions, convert_routes
from icrsumo.world.networks import load_net
from icrsumo.world.routes import read_routes
from icrsumo.world.scenario import find_scenarios, read_scenario

pytestmark = pytest.mark.sumo

ROOT = Path(__file__).resolve().parents[2]
EVAL_SPLITS = ("tiny", "short", "long")


def _node_types(net) -> Counter:
    return Counter(n.getType() for n in net.sumolib_net.getNodes())


def _own_towns() -> dict:
    return {t: p for t, p in bundled_towns().items() if p.parent.name == "networks"}


def test_six_own_towns_not_named_like_carla():
    towns = _own_towns()
    assert len(towns) >= 6
    assert not any(re.fullmatch(r"(?i)town\d+(hd)?", t) for t in towns)
    assert sum(p.stat().st_size for p in towns.values()) < 8_000_000


def test_towns_cover_langauto_features():
    nets = {t: load_net(p) for t, p in _own_towns().items()}
    types = {t: _node_types(n) for t, n in nets.items()}
    max_lanes = {t: max(len(v) for v in n.passenger_lanes.values()) for t, n in nets.items()}
    # signalised 4-way intersections with one lane each way
    assert types["icr_grid"]["traffic_light"] >= 4 and max_lanes["icr_grid"] == 1
    # T-junctions: nodes where exactly three roads meet
    sn = nets["icr_tjunctions"].sumolib_net
    def neighbours(n):
        ids = {e.getFromNode().getID() for e in n.getIncoming()}
        ids |= {e.getToNode().getID() for e in n.getOutgoing()}
        return ids - {n.getID()}
    tees = [n for n in sn.getNodes() if len(neighbours(n)) == 3]
    assert len(tees) >= 6
    # multi-lane arterial with lanes restricted so that lane changes are needed
    assert max_lanes["icr_arterial"] >= 2
    # roundabout
    assert nets["icr_roundabout"].roundabout_edges
    # highway: 3+ lanes
    assert max_lanes["icr_highway"] >= 3
    # stop signs somewhere
    assert sum(t["priority_stop"] + t["allway_stop"] for t in types.values()) >= 3
    # rural curves: some edge turns by more than 30 degrees along its shape
    rural = nets["icr_rural"]
    def turn(shape):
        h = [math.atan2(b[1] - a[1], b[0] - a[0]) for a, b in zip(shape[:-1], shape[1:])]
        return max((abs((y - x + math.pi) % (2 * math.pi) - math.pi) for x, y in zip(h, h[1:])),
                   default=0.0)
    curved = [e for e in rural.passenger_lanes
              if sum(1 for _ in rural.lane_shape[f"{e}_0"]) > 3]
    assert sum(turn(rural.lane_shape[f"{e}_0"]) for e in curved) > math.radians(30)
    # sidewalks and pedestrian crossings in the urban towns
    for t in ("icr_grid", "icr_tjunctions", "icr_arterial"):
        assert nets[t].has_sidewalks
        assert any(e.getFunction() == "crossing" for e in nets[t].sumolib_net.getEdges())
    # every town is strongly connected for cars
    for t, n in nets.items():
        start = sorted(n.passenger_lanes)[0]
        reach = n.shortest_paths(start, 0.0, set(n.passenger_lanes))
        assert set(reach) | {start} == set(n.passenger_lanes), t


@pytest.mark.parametrize(("tool", "folder"), [("make_networks.py", "networks"), ("make_routes.py", "routes"),
                                              ("make_carla_routes.py", "routes/carla-train"),
                                              ("make_carla_focus.py", "routes/carla-focus"),
                                              ("make_carla_fidelity.py", "routes/carla-fidelity")])
def test_tools_regenerate_byte_identical(tmp_path, tool, folder):
    subprocess.run([sys.executable, str(ROOT / "tools" / tool), "--out", str(tmp_path)],
                   check=True, capture_output=True, timeout=600)
    theirs = sorted(p.name for p in (ROOT / folder).iterdir() if p.is_file())  # subfolders: other tools
    assert sorted(p.name for p in tmp_path.iterdir()) == theirs
    match, mismatch, errors = filecmp.cmpfiles(ROOT / folder, tmp_path, theirs, shallow=False)
    assert mismatch == [] and errors == []


def test_split_files_and_train_disjoint(converted):
    towns = {t for t in bundled_towns() if t.startswith("icr_")}  # icrsumo's own towns
    counts = {"tiny": 16, "short": 16, "long": 32}
    seen_towns: set[str] = set()
    for split, n in counts.items():
        routes, errors = read_routes(bundled_suites()[split])
        assert errors == [] and len(routes) == n
        assert len({r.town for r in routes}) >= len(towns) - 1
        seen_towns.update(r.town for r in routes)
    assert seen_towns == towns
    train, errors = read_routes(bundled_suites()["train"])
    assert errors == [] and len(train) > 64 and {r.town for r in train} == towns
    ids = [r.id for s in (*EVAL_SPLITS, "train") for r in read_routes(bundled_suites()[s])[0]]
    assert len(ids) == len(set(ids))
    # no train route drives an evaluation route's edge sequence
    eval_edges = {read_scenario(d).ego_edges for s in EVAL_SPLITS for d in find_scenarios(converted[s])}
    tmp = converted["tiny"].parent / "train_check"
    rep = convert_routes(bundled_suites()["train"], tmp, ConvertOptions(traffic="none", workers=2))
    assert rep.failures == []
    train_edges = {read_scenario(d).ego_edges for d in find_scenarios(tmp)}
    assert len(train_edges) == len(train)
    assert not (train_edges & eval_edges)


def test_split_lengths_and_maneuvers(converted):
    bounds = {"tiny": (0, 150), "short": (150, 500), "long": (500, 10_000)}
    min_turns = {"tiny": 1, "short": 1, "long": 3}
    dirs: Counter = Counter()
    changes = 0
    for split, out in converted.items():
        lengths = []
        for d in find_scenarios(out):
            sc = read_scenario(d)
            lo, hi = bounds[split]
            assert lo <= sc.length < hi, (split, sc.route_id, sc.length)
            turns = [j["direction"] for j in sc.manifest["junctions"] if j["choice"]]
            assert len(turns) >= min_turns[split], (split, sc.route_id)
            dirs.update(t.lower() for t in turns)
            changes += len(sc.manifest["lane_changes"])
            lengths.append(sc.length)
        if split == "long":
            assert 550 <= sum(lengths) / len(lengths) <= 680
    assert min(dirs["l"], dirs["r"], dirs["s"]) >= 10, dirs
    assert changes >= 5


def test_bundled_conversion_byte_identical(converted, tmp_path):
    out = tmp_path / "again"
    rep = convert_routes(bundled_suites()["tiny"], out, ConvertOptions(workers=1))
    assert rep.failures == [] and len(rep.converted) == 16
    a = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    b = {p.relative_to(converted["tiny"]): p.read_bytes()
         for p in converted["tiny"].rglob("*") if p.is_file()}
    assert a == b


def test_every_bundled_scenario_inserts_ego_in_libsumo(converted):
    from icrsumo.sim import SumoSession

    for split, out in converted.items():
        for d in find_scenarios(out):
            sc = read_scenario(d)
            with SumoSession(sc) as s:
                s.run_until(sc.ego_depart)
                assert s.insert_ego(), (split, sc.route_id)
                st = s.ego_state()
                assert st["route"] == sc.ego_edges
                assert math.hypot(st["x"] - sc.start[0], st["y"] - sc.start[1]) < 1.0
