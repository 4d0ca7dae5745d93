"""Leaderboard route XML reading: good files, per-route errors, file-level errors."""

from __future__ import annotations

import pytest

from icrsumo.errors import InputError
from icrsumo.routes import format_routes, read_routes


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
