"""convert-routes on the hand-made OpenDRIVE town in CARLA coordinates, and its error paths."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest

from icrsumo.app.cli.main import main
from icrsumo.core.errors import InputError
from icrsumo.world.convert import ConvertOptions, convert_routes, route_seed, safe_name
from icrsumo.world.scenario import find_scenarios, read_scenario

pytestmark = pytest.mark.sumo


def _tree_bytes(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_carla_coords_match_expected_edges(carla_mini_out, data_dir):
    expected = json.loads((data_dir / "carla_mini_expected.json").read_text())
    dirs = find_scenarios(carla_mini_out)
    assert len(dirs) == 3
    got = {read_scenario(d).route_id: read_scenario(d) for d in dirs}
    routes = expected["routes"].get("carla_mini_routes", expected["routes"])
    words = {"l": "left", "r": "right", "s": "straight"}
    for rid, exp in routes.items():
        sc = got[rid]
        assert list(sc.ego_edges) == exp["edges"]
        turns = [words[j["direction"]] for j in sc.manifest["junctions"] if j["choice"]]
        assert turns == exp["maneuvers"]
        assert sc.length > 50
        net_off = sc.manifest["net"]
        assert net_off.startswith("../../networks/carla_mini-")


def test_scenario_files_are_complete(carla_mini_out):
    for d in find_scenarios(carla_mini_out):
        sc = read_scenario(d)
        assert sc.sumocfg.is_file() and sc.net.is_file()
        m = sc.manifest
        assert m["traffic"]["n_vehicles"] > 0
        assert (d / m["traffic"]["vehicles"]).is_file()
        assert (d / "ego.rou.xml").read_text().count(" ".join(sc.ego_edges)) == 1
        poly = sc.polyline
        assert abs(poly[0][0] - sc.start[0]) < 0.05 and abs(poly[0][1] - sc.start[1]) < 0.05
        assert sc.seed == route_seed(0, sc.route_id)
    assert not [p for p in (carla_mini_out / "scenarios").iterdir() if p.name.startswith(".")]


def test_scenario_records_are_what_convert_wrote(carla_mini_out):
    """read_scenario's typed records hold the manifest's values: the route with its junction
    passes and lane changes (as routing produced them), the ego, the traffic."""
    from dataclasses import asdict

    for d in find_scenarios(carla_mini_out):
        sc = read_scenario(d)
        m, route = sc.manifest, sc.route
        assert route.junctions and [asdict(j) for j in route.junctions] == m["junctions"]
        assert [dict(asdict(c), direction=c.direction) for c in route.lane_changes] == m["lane_changes"]
        assert (list(route.edges), [list(x) for x in route.lanes], list(route.lane_path)) == \
            (m["ego"]["edges"], m["ego"]["lanes"], m["ego"]["lane_path"])
        assert (asdict(route.start), asdict(route.end)) == (m["ego"]["start"], m["ego"]["end"])
        assert [list(p) for p in route.polyline] == m["route"]["polyline"]
        assert [list(p) for p in sc.key_points] == m["waypoints"] and len(sc.key_points) >= 2
        assert list(route.headings) == m["route"]["headings"] and route.length == m["route"]["length"]
        assert asdict(sc.ego) == {"vtype": m["ego"]["vtype"], "sumo_route": m["ego"]["route"],
                                  **{k: m["ego"][k] for k in ("depart", "length", "width")}}
        t = m["traffic"]
        assert (sc.traffic.level, sc.traffic.end, sc.traffic.n_vehicles, sc.traffic.n_pedestrians,
                sc.traffic.max_vehicles) == (t["level"], t["end"], t["n_vehicles"], t["n_pedestrians"],
                                             t["max_vehicles"])
        assert (sc.step_length, sc.source_hash) == (m["step_length"], m["source_hash"])


def test_conversion_is_byte_identical_and_reused(tmp_path, data_dir):
    outs = []
    for name in ("a", "b"):
        out = tmp_path / name
        rep = convert_routes(
            data_dir / "langauto_style_routes.xml", out,
            ConvertOptions(coords="carla", xodr=data_dir / "carla_mini.xodr", workers=1 + (name == "b")),
        )
        assert rep.failures == [] and len(rep.converted) == 3
        outs.append(_tree_bytes(out))
    assert outs[0] == outs[1]
    rep = convert_routes(
        data_dir / "langauto_style_routes.xml", tmp_path / "a",
        ConvertOptions(coords="carla", xodr=data_dir / "carla_mini.xodr"),
    )
    assert rep.reused == ["0", "10", "12"] and rep.converted == []
    assert _tree_bytes(tmp_path / "a") == outs[0]


def test_wrong_frame_fails_per_route_with_exit_2(tmp_path, data_dir, capsys):
    # the same CARLA-frame file read as SUMO coordinates lies off the map
    code = main(["convert-routes", str(data_dir / "carla_mini_routes.xml"), "--out",
                 str(tmp_path / "o"), "--xodr", str(data_dir / "carla_mini.xodr")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1  # no route converted: the first route's error, nothing written
    assert "carla_mini_routes.xml: route 0, waypoint 1: no drivable path" in err[0]
    assert not (tmp_path / "o").exists()


def test_one_bad_route_does_not_stop_the_others(tmp_path, data_dir, capsys):
    text = (data_dir / "langauto_style_routes.xml").read_text()
    # move route 10's first waypoint 500 m off the map
    head, tail = text.split('<route id="10"')
    m = re.search(r'x="(-?[0-9.]+)"', tail)
    tail = tail[:m.start()] + f'x="{float(m.group(1)) + 500:.2f}"' + tail[m.end():]
    broken = head + '<route id="10"' + tail
    p = tmp_path / "broken.xml"
    p.write_text(broken)
    code = main(["convert-routes", str(p), "--out", str(tmp_path / "o"), "--coords", "carla",
                 "--xodr", str(data_dir / "carla_mini.xodr"), "--workers", "1"])
    err = capsys.readouterr().err
    assert code == 2
    assert "route 10, waypoint 0" in err and "fix:" in err
    done = sorted(d.name for d in (tmp_path / "o" / "scenarios").iterdir())
    assert done == ["0", "12"]
    index = json.loads((tmp_path / "o" / "index.json").read_text())
    assert [s["id"] for s in index["scenarios"]] == ["0", "12"]
    assert len(index["failures"]) == 1


def test_unknown_town_and_net_dir(tmp_path, data_dir, capsys):
    code = main(["convert-routes", str(data_dir / "carla_mini_routes.xml"), "--out",
                 str(tmp_path / "o"), "--coords", "carla"])
    err = capsys.readouterr().err
    assert code == 2 and "unknown town 'CarlaMini'" in err and "--net-dir" in err
    nets = tmp_path / "nets"
    nets.mkdir()
    (nets / "CarlaMini.xodr").write_bytes((data_dir / "carla_mini.xodr").read_bytes())
    code = main(["convert-routes", str(data_dir / "carla_mini_routes.xml"), "--out",
                 str(tmp_path / "o"), "--coords", "carla", "--net-dir", str(nets)])
    assert code == 0
    assert len(find_scenarios(tmp_path / "o")) == 3


def test_no_path_between_waypoints(tmp_path, data_dir, carla_mini_out):
    # waypoint 1 on an inbound edge's start cannot be reached from an outbound edge's end
    sc = read_scenario(find_scenarios(carla_mini_out)[0])
    net = sc.net
    p = tmp_path / "r.xml"
    from icrsumo.world.networks import load_net

    rn = load_net(net)
    out_edge, in_edge = sc.ego_edges[-1], sc.ego_edges[0]
    x0, y0, _ = rn.lane_pose(f"{out_edge}_0", rn.edge_length[out_edge] - 1)
    x1, y1, _ = rn.lane_pose(f"{in_edge}_0", 1.0)
    p.write_text(f'<routes><route id="x" town="t"><waypoint x="{x0}" y="{y0}"/>'
                 f'<waypoint x="{x1}" y="{y1}"/></route></routes>')
    # a 1 m snap radius leaves only the dead-end lane (no U-turns in this net)
    rep = convert_routes(p, tmp_path / "o", ConvertOptions(net=net, max_snap=1.0))
    assert len(rep.failures) == 1
    assert "route x, waypoint 1: no drivable path from waypoint 0 to waypoint 1" in rep.failures[0]


def test_file_level_errors_write_nothing(tmp_path, capsys):
    p = tmp_path / "bad.xml"
    p.write_text("<routes><route id='1'>")
    code = main(["convert-routes", str(p), "--out", str(tmp_path / "o")])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.xml: line 1" in err[0] and "Traceback" not in err[0]
    assert not (tmp_path / "o").exists()
    code = main(["convert-routes", str(p), "--out", str(tmp_path / "o"), "--net",
                 str(tmp_path / "missing.net.xml")])
    assert code == 2


def test_options_checked():
    with pytest.raises(InputError, match="more than one network source"):
        ConvertOptions(net=Path("a"), xodr=Path("b")).check()
    assert safe_name("a/b c") == "a_b_c" and safe_name("..") == "route_.."


def test_plain_sumo_runs_a_scenario(carla_mini_out):
    from icrsumo.core.resources import sumo_binary

    sc = read_scenario(find_scenarios(carla_mini_out)[0])
    proc = subprocess.run([sumo_binary("sumo"), "-c", str(sc.sumocfg), "--end", "60"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "Error" not in proc.stderr


def test_ego_inserts_in_libsumo(carla_mini_out):
    from icrsumo.sim import SumoSession

    for d in find_scenarios(carla_mini_out):
        sc = read_scenario(d)
        with SumoSession(sc) as s:
            s.run_until(sc.ego_depart)
            assert s.insert_ego()
            st = s.ego_state()
            assert st["route"] == sc.ego_edges and st["road"] == sc.ego_edges[0]
            assert abs(st["x"] - sc.start[0]) < 0.5 and abs(st["y"] - sc.start[1]) < 0.5
