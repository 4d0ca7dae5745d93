"""CARLA's eight LangAuto towns and LangAuto's three route files ship with the package and need
no flags: towns resolve by name, the suites know their coordinate frame."""

from __future__ import annotations

import filecmp
import json
import subprocess
import sys
from pathlib import Path

import pytest

from icrsumo.core.resources import bundled_suites, bundled_towns, suite_coords
from icrsumo.world.networks import load_net
from icrsumo.world.routes import read_routes

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
CARLA_TOWNS = ("Town01", "Town02", "Town03", "Town04", "Town05", "Town06", "Town07", "Town10HD")
TRACKS = {"langauto-tiny": ("benchmark_tiny.xml", 16), "langauto-short": ("benchmark_short.xml", 16),
          "langauto-long": ("benchmark_long.xml", 32)}


def test_carla_towns_are_bundled_with_their_notice():
    towns = bundled_towns()
    assert set(CARLA_TOWNS) <= set(towns)
    folder = towns["Town01"].parent
    assert all(towns[t].parent == folder for t in CARLA_TOWNS)
    notice = (folder / "LICENSE-CARLA.txt").read_text(encoding="utf-8")
    assert "MIT" in notice
    readme = (folder / "README.md").read_text(encoding="utf-8")
    assert "CARLA project" in readme and "CC-BY" in readme
    assert sum(towns[t].stat().st_size for t in CARLA_TOWNS) < 6_000_000


def test_carla_towns_have_sidewalks_and_crossings():
    for town in ("Town02", "Town10HD"):
        net = load_net(bundled_towns()[town])
        assert net.has_sidewalks, town
        assert net.crossing_nodes, town
        walking = [e for e in net.sumolib_net.getEdges(withInternal=True) if e.getFunction() == "walkingarea"]
        assert walking, town


def test_only_real_roundabouts_are_marked():
    """Town03's roundabout (ring radius 18-29 m) stays marked; Town06's highway loop (73-90 m),
    which the source networks mark as a roundabout, is not one."""
    import numpy as np

    marked = {}
    for town in CARLA_TOWNS:
        sn = load_net(bundled_towns()[town]).sumolib_net
        for r in sn.getRoundabouts():
            xy = np.array([sn.getNode(n).getCoord()[:2] for n in r.getNodes()])
            radius = float(np.hypot(*(xy - xy.mean(axis=0)).T).max())
            assert radius <= 50.0, (town, r.getEdges(), radius)
            marked[town] = marked.get(town, 0) + 1
    assert marked == {"Town03": 1}
    assert not load_net(bundled_towns()["Town06"]).roundabout_edges


@pytest.mark.skipif(not (SHARED / "carla").is_dir(), reason="needs ../shared/carla (the source networks)")
def test_carla_towns_regenerate_byte_identical(tmp_path):
    subprocess.run([sys.executable, str(ROOT / "tools" / "make_carla_networks.py"), "--out", str(tmp_path)],
                   check=True, capture_output=True, timeout=600)
    theirs = sorted(p.name for p in bundled_towns()["Town01"].parent.iterdir())
    assert sorted(p.name for p in tmp_path.iterdir()) == theirs
    _, mismatch, errors = filecmp.cmpfiles(bundled_towns()["Town01"].parent, tmp_path, theirs, shallow=False)
    assert mismatch == [] and errors == []


def test_langauto_suites_are_bundled_in_carla_coordinates():
    suites = bundled_suites()
    for name, (_, count) in TRACKS.items():
        routes, errors = read_routes(suites[name])
        assert errors == [] and len(routes) == count, name
        assert {r.town for r in routes} <= set(CARLA_TOWNS)
        assert suite_coords(name) == "carla"
    assert suite_coords("tiny") == "sumo" and suite_coords("no-such-suite") is None
    folder = suites["langauto-tiny"].parent
    meta = json.loads((folder / "suite.json").read_text(encoding="utf-8"))
    assert meta["coords"] == "carla" and "Apache" in meta["source"]
    notice = (folder / "NOTICE.md").read_text(encoding="utf-8")
    assert "LMDrive" in notice and "Apache License" in notice


@pytest.mark.skipif(not (SHARED / "langauto").is_dir(), reason="needs ../shared/langauto")
def test_langauto_route_files_are_lmdrives_own():
    for name, (source, _) in TRACKS.items():
        assert bundled_suites()[name].read_bytes() == (SHARED / "langauto" / source).read_bytes()


@pytest.mark.sumo
def test_convert_routes_needs_no_flags_for_a_langauto_suite(tmp_path):
    """A route file in CARLA coordinates over CARLA towns converts with --coords carla alone (the
    towns resolve by name: no --net-dir)."""
    text = bundled_suites()["langauto-tiny"].read_text(encoding="utf-8")
    one = tmp_path / "two.xml"
    start = text.index("<routes>") + len("<routes>")
    first = text[start:text.index("</route>", text.index("</route>") + 1) + len("</route>")]
    one.write_text(text[:start] + first + "\n</routes>\n", encoding="utf-8")
    assert len(read_routes(one)[0]) == 2
    res = subprocess.run([sys.executable, "-m", "icrsumo", "convert-routes", str(one), "--coords", "carla",
                          "--out", str(tmp_path / "out"), "--workers", "1"],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    assert "2 converted" in res.stderr and "0 failed" in res.stderr  # the summary goes to stderr
    manifests = (tmp_path / "out" / "scenarios").glob("*/scenario.json")
    towns = {json.loads(p.read_text())["town"] for p in manifests}
    assert towns <= set(CARLA_TOWNS) and towns


@pytest.mark.sumo
def test_a_langauto_route_runs_by_suite_name_alone(cache):
    from icrsumo.agents.privileged import RouteOracle
    from icrsumo.evaluation.bundled import bundled_route
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.scoring import score_episode
    from icrsumo.sim.episode import run_episode
    from icrsumo.world.scenario import read_scenario

    sc_dir, instr = bundled_route("0", "langauto-tiny")
    sc = read_scenario(sc_dir)
    assert sc.town == "Town01" and sc.manifest["source"]["coords"] == "carla"
    log = run_episode(sc, read_instruction_sets(instr)[0], RouteOracle())
    assert score_episode(log).rc == 100.0
