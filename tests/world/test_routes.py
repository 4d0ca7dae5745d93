"""Leaderboard route XML reading: good files, per-route errors, file-level errors."""

from __future__ import annotations

import subprocess
import sys

import pytest

from icrsumo.core.errors import InputError
from icrsumo.core.resources import bundled_suites
from icrsumo.world.routes import check_route_selection, format_routes, read_routes, route_ids, suite_file


def _write(tmp_path, text: str):
    p = tmp_path / "r.xml"
    p.write_text(text, encoding="utf-8")
    return p


def test_reads_langauto_layout(data_dir):
    routes, errors = read_routes(data_dir / "langauto_style_routes.xml")
    assert errors == []
    assert [r.id for r in routes] == ["0", "10", "12"]
    r = routes[0]
    assert r.town and len(r.waypoints) >= 2
    assert dict(r.weather)["id"]  # weather attributes kept verbatim, id included


def test_per_route_errors_name_route_and_waypoint(tmp_path):
    p = _write(tmp_path, """<routes>
      <route id="a" town="t"><waypoint x="1" y="2"/><waypoint x="3" y="4"/></route>
      <route id="b" town="t"><waypoint x="1"/><waypoint x="3" y="4"/></route>
      <route id="c" town="t"><waypoint x="1" y="2"/><waypoint x="nan" y="4"/></route>
      <route id="d" town="t"><waypoint x="1" y="2"/></route>
      <route town="t"><waypoint x="1" y="2"/><waypoint x="3" y="4"/></route>
      <route id="a" town="t"><waypoint x="1" y="2"/><waypoint x="3" y="4"/></route>
    </routes>""")
    routes, errors = read_routes(p)
    assert [r.id for r in routes] == ["a"]
    lines = {i: e.line() for i, e in errors}
    assert "route b, waypoint 0: missing attribute 'y'" in lines[1]
    assert "route c, waypoint 1" in lines[2] and "not finite" in lines[2]
    assert "route d" in lines[3] and "needs at least 2" in lines[3]
    assert "route #4" in lines[4] and "missing attribute 'id'" in lines[4]
    assert "duplicate route id" in lines[5]
    assert all(str(p) in line and "(fix:" in line for line in lines.values())


@pytest.mark.parametrize(
    "text, expect",
    [
        ("<routes><route id='1'>", "line 1"),
        ("<foo/>", "expected <routes>"),
        ("<routes/>", "contains no <route>"),
        ('<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaa">]><routes>&a;</routes>',
         "forbidden XML construct"),
    ],
)
def test_file_level_errors(tmp_path, text, expect):
    with pytest.raises(InputError) as err:
        read_routes(_write(tmp_path, text))
    assert expect in err.value.line()
    assert "\n" not in err.value.line()


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        read_routes(tmp_path / "nope.xml")


def test_format_roundtrip(tmp_path, data_dir):
    routes, _ = read_routes(data_dir / "carla_mini_routes.xml")
    p = _write(tmp_path, format_routes(routes))
    again, errors = read_routes(p)
    assert errors == []
    assert [(r.id, r.town, len(r.waypoints), r.weather) for r in again] == [
        (r.id, r.town, len(r.waypoints), r.weather) for r in routes
    ]
    assert again[0].waypoints[0].x == pytest.approx(routes[0].waypoints[0].x, abs=0.005)


def _icrsumo(*argv: str, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "icrsumo", *argv], cwd=cwd, capture_output=True, text=True,
                          timeout=300)


def _two_routes(tmp_path, town: str = "NoSuchTown"):
    return _write(tmp_path, f"""<routes>
      <route id="r_one" town="{town}"><waypoint x="1" y="2"/><waypoint x="3" y="4"/></route>
      <route id="r_two" town="{town}"><waypoint x="1" y="2"/><waypoint x="3" y="4"/></route>
    </routes>""")


def test_a_mistyped_route_id_is_refused_before_the_suite_is_converted(tmp_path):
    """The ids come from the route file: a typo is named with its closest ids before any route
    is converted (here no route could be: their town does not exist, which a conversion would
    report first), and nothing is written."""
    routes, out = _two_routes(tmp_path), tmp_path / "out"
    for command in ("evaluate", "attack"):
        run = _icrsumo(command, "--suite", str(routes), "--routes", "r_one,r_tow", "--out", str(out),
                       cwd=tmp_path)
        err = run.stderr.strip().splitlines()
        assert run.returncode == 2 and len(err) == 1, run.stderr
        assert "--routes: 'r_tow': no such route in the suite" in err[0] and "did you mean r_two" in err[0]
        assert "NoSuchTown" not in err[0] and not out.exists()
    run = _icrsumo("evaluate", "--routes", "tiny_03", "--out", str(out), cwd=tmp_path)
    assert run.returncode == 2 and "did you mean" in run.stderr and "tiny_003" in run.stderr
    assert not out.exists()


@pytest.mark.parametrize("argv", [["evaluate", "--suite", "{arg}"], ["attack", "--suite", "{arg}"],
                                  ["list", "routes", "--suite", "{arg}"], ["convert-routes", "{arg}"]])
def test_a_missing_route_file_is_named_as_missing_not_as_an_unknown_suite(tmp_path, argv):
    out = tmp_path / "out"
    extra = ["--out", str(out)] if argv[0] != "list" else []
    for arg in ("routes/mine.xml", "mine.xml"):
        run = _icrsumo(*[a.format(arg=arg) for a in argv], *extra, cwd=tmp_path)
        suites = ", ".join(bundled_suites())
        err = run.stderr.strip().splitlines()
        assert run.returncode == 2
        assert err == [f"icrsumo: error: {arg}: no such route file (fix: check the path; or give a bundled "
                       f"suite: {suites})"]
    run = _icrsumo(*[a.format(arg="tinny") for a in argv], *extra, cwd=tmp_path)
    assert run.returncode == 2 and "unknown suite (fix: did you mean tiny or train?" in run.stderr
    assert not out.exists()


def test_suite_file_and_route_ids(tmp_path):
    routes = _two_routes(tmp_path)
    assert suite_file(str(routes)) == routes and suite_file("tiny") == bundled_suites()["tiny"]
    assert route_ids(routes) == ["r_one", "r_two"]
    (tmp_path / "conv").mkdir()
    (tmp_path / "conv" / "index.json").write_text("{}")
    assert suite_file(str(tmp_path / "conv"), folders=True) is None
    with pytest.raises(InputError, match="is a folder, not a route XML file"):
        suite_file(str(tmp_path / "conv"))
    check_route_selection(["r_two"], ["r_one", "r_two"], "routes", "mine")
    with pytest.raises(InputError, match=r"routes: 'x': no such route in the suite mine \(fix: use the"):
        check_route_selection(["r_one", "x"], ["r_one", "r_two"], "routes", "mine")


def test_the_python_api_checks_the_suite_and_its_route_ids_before_converting(tmp_path):
    """``icrsumo.evaluate`` names a mistyped route id and a missing route file in its own field
    words, before any route is converted, and writes nothing."""
    import icrsumo

    routes, out = _two_routes(tmp_path), tmp_path / "out"
    with pytest.raises(InputError, match=r"^routes: 'r_tow': no such route in the suite .*did you mean r_tw"):
        icrsumo.evaluate(suite=str(routes), routes=["r_one", "r_tow"], out=str(out))
    with pytest.raises(InputError, match=r"rollout_route: 'r_three': no such route"):
        icrsumo.evaluate(suite=str(routes), routes=["r_one"], rollout_route="r_three", out=str(out))
    with pytest.raises(InputError, match=r"no such route file"):
        icrsumo.evaluate(suite=str(tmp_path / "mine.xml"), out=str(out))
    assert not out.exists()
