"""Leaderboard-style route XML: reading (safely, with per-route errors) and writing."""

from __future__ import annotations

import math
from pathlib import Path
from xml.etree.ElementTree import Element, ParseError

from defusedxml import DefusedXmlException
from defusedxml.ElementTree import parse as safe_parse

from .errors import InputError
from .types import RouteSpec, Waypoint


def parse_xml_file(path: Path, expected_root: str | None = None) -> Element:
    """Parse an untrusted XML file without DTDs or entity expansion; errors are InputErrors."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "", "file not found", "check the path")
    try:
        root = safe_parse(str(path), forbid_dtd=True).getroot()
    except ParseError as err:
        line, col = err.position
        raise InputError(
            path, f"line {line}, column {col}", "malformed XML", "fix the XML syntax there"
        ) from None
    except DefusedXmlException as err:
        raise InputError(
            path, "", f"forbidden XML construct ({type(err).__name__})",
            "remove the DOCTYPE / entity declarations",
        ) from None
    if expected_root is not None and root.tag != expected_root:
        raise InputError(
            path, f"root element <{root.tag}>", f"expected <{expected_root}>",
            f"use a leaderboard route file whose root is <{expected_root}>",
        )
    return root


def _float_attr(el: Element, name: str, path: Path, place: str, required: bool) -> float | None:
    raw = el.get(name)
    if raw is None:
        if required:
            raise InputError(path, place, f"missing attribute '{name}'", f"add {name}=\"...\"")
        return None
    try:
        value = float(raw)
    except ValueError:
        raise InputError(
            path, place, f"attribute {name}={raw!r} is not a number", "write a decimal number"
        ) from None
    if not math.isfinite(value):
        raise InputError(path, place, f"attribute {name}={raw!r} is not finite", "use a finite number")
    return value


def _parse_route(el: Element, index: int, path: Path) -> RouteSpec:
    rid = el.get("id")
    if rid is None or not rid.strip():
        raise InputError(path, f"route #{index}", "missing attribute 'id'", 'add id="..."')
    place = f"route {rid}"
    waypoints = []
    for k, wp in enumerate(el.findall("waypoint")):
        wplace = f"{place}, waypoint {k}"
        x = _float_attr(wp, "x", path, wplace, True)
        y = _float_attr(wp, "y", path, wplace, True)
        extra = {n: _float_attr(wp, n, path, wplace, False) for n in ("z", "pitch", "roll", "yaw")}
        waypoints.append(
            Waypoint(
                x=x, y=y, z=extra["z"] or 0.0, pitch=extra["pitch"] or 0.0,
                roll=extra["roll"] or 0.0, yaw=extra["yaw"],
            )
        )
    if len(waypoints) < 2:
        raise InputError(
            path, place, f"has {len(waypoints)} waypoint(s), needs at least 2",
            "give a start and an end <waypoint>",
        )
    weather_el = el.find("weather")
    weather = tuple(weather_el.attrib.items()) if weather_el is not None else ()
    return RouteSpec(
        id=rid.strip(), town=(el.get("town") or "").strip(), waypoints=tuple(waypoints),
        weather=weather, index=index,
    )


def read_routes(path: Path) -> tuple[list[RouteSpec], list[tuple[int, InputError]]]:
    """Read a leaderboard route file: the good routes and (route index, error) per bad route.

    A file-level problem (missing file, malformed XML, wrong root, no route) raises InputError.
    Duplicate route ids are errors of the later routes.
    """
    path = Path(path)
    root = parse_xml_file(path, expected_root="routes")
    elements = root.findall("route")
    if not elements:
        raise InputError(path, "<routes>", "contains no <route>", "add <route id=... town=...>")
    routes: list[RouteSpec] = []
    errors: list[tuple[int, InputError]] = []
    seen: set[str] = set()
    for i, el in enumerate(elements):
        try:
            spec = _parse_route(el, i, path)
        except InputError as err:
            errors.append((i, err))
            continue
        if spec.id in seen:
            errors.append((i, InputError(
                path, f"route {spec.id}", "duplicate route id", "give every route a unique id")))
            continue
        seen.add(spec.id)
        routes.append(spec)
    return routes, errors


def _fmt(v: float) -> str:
    return f"{v:.2f}"


def format_routes(routes: list[RouteSpec]) -> str:
    """Leaderboard route XML text for ``routes``, laid out like CARLA's route files."""
    lines = ["<?xml version='1.0' encoding='utf-8'?>", "<routes>"]
    for r in routes:
        lines.append(f'   <route id="{r.id}" town="{r.town}">')
        for w in r.waypoints:
            yaw = "" if w.yaw is None else f' yaw="{_fmt(w.yaw)}"'
            lines.append(
                f'      <waypoint pitch="{_fmt(w.pitch)}" roll="{_fmt(w.roll)}" x="{_fmt(w.x)}"'
                f' y="{_fmt(w.y)}"{yaw} z="{_fmt(w.z)}" />'
            )
        if r.weather:
            attrs = " ".join(f'{k}="{v}"' for k, v in r.weather)
            lines.append(f"      <weather {attrs} />")
        lines.append("   </route>")
    lines.append("</routes>")
    return "\n".join(lines) + "\n"
