"""Leaderboard-style route XML: reading (safely, with per-route errors) and writing, and the
check that every XML file the package hands to a parser (route files, networks, OpenDRIVE,
a scenario's SUMO config and route files) declares no DTD or entities."""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Iterable
from functools import lru_cache
from pathlib import Path
from xml.etree.ElementTree import Element, ParseError

from defusedxml import DefusedXmlException
from defusedxml.ElementTree import parse as safe_parse

from icrsumo.core.errors import Field, InputError, short
from icrsumo.core.fsio import BOMS, unreadable
from icrsumo.core.types import RouteSpec, Waypoint

#: bytes read per step by :func:`check_xml_file`
_CHUNK = 1 << 20
#: what may follow ``<!`` in a file the package reads: a comment or a CDATA section
_ALLOWED_DECL = (b"--", b"[CDATA[")
_ENCODING = re.compile(rb"""\A\s*<\?xml\b[^>]*?\bencoding\s*=\s*["']([^"']*)["']""")
#: encodings in which the bytes of ``<!DOCTYPE`` are those of ASCII (what the scan looks for)
_ASCII_ENCODINGS = frozenset({"utf-8", "utf8", "us-ascii", "ascii", "iso-8859-1", "iso8859-1",
                              "latin-1", "latin1"})
#: waypoint coordinates (m) and angles (degrees) beyond these are no place on a map
MAX_COORD_M = 1e7
MAX_ANGLE_DEG = 1e4


def _line_of(path: Path, offset: int) -> int:
    """1-based line number of byte ``offset`` of the file (read again, on the error path only)."""
    n, done = 1, 0
    with open(path, "rb") as fh:
        while done < offset:
            block = fh.read(min(_CHUNK, offset - done))
            if not block:
                break
            n += block.count(b"\n")
            done += len(block)
    return n


def check_xml_file(path: Path, what: str = "XML file", fix: str = "") -> None:
    """InputError unless ``path`` is a readable file of ASCII-compatible XML (UTF-8, ASCII or
    Latin-1; no UTF-16/32, no NUL byte) with no ``<!DOCTYPE``/``<!ENTITY``/other markup
    declaration anywhere: after ``<!`` only a comment or a CDATA section may start. The whole
    file is scanned in 1 MiB blocks (a declaration split across two blocks is seen), so a
    declaration after a long comment is found before any parser (sumolib, SUMO, netconvert)
    reads the file. ``what`` names the file in the message ("network file"), ``fix`` says where
    it comes from. Scans about 1 GB/s; each file is scanned once per process while unchanged."""
    path = Path(path)
    try:
        st = path.stat()
    except OSError as err:
        raise unreadable(path, what, fix, err) from None
    if not path.is_file():
        raise InputError(path, "", f"is a folder, not a {what}" if path.is_dir() else f"{what} is not a file",
                         fix or "pass the file")
    _check_xml_cached(str(path.resolve()), st.st_mtime_ns, st.st_size, str(path), what, fix)


@lru_cache(maxsize=256)
def _check_xml_cached(real: str, mtime_ns: int, size: int, shown: str, what: str, fix: str) -> None:
    path = Path(shown)
    try:
        with open(real, "rb") as fh:
            _scan(fh, path, Path(real), what, fix)
    except OSError as err:
        raise unreadable(path, what, fix, err) from None


def _scan(fh, path: Path, real: Path, what: str, fix: str) -> None:
    """The scan of :func:`check_xml_file` over the open file ``fh`` (``real``: its path)."""
    need = 2 + len(_ALLOWED_DECL[1])  # bytes from "<" on that decide what "<!" starts
    block = fh.read(_CHUNK)
    _check_head(path, block, what, fix)
    carry, base = b"", 0  # base: file offset of data[0]
    while True:
        nul = block.find(b"\x00")
        if nul >= 0:
            raise InputError(path, f"line {_line_of(real, base + len(carry) + nul)}",
                             f"{what} holds a NUL byte (not UTF-8 text)", "save it as UTF-8 XML")
        data = carry + block
        limit = len(data) - need + 1 if block else len(data)  # "<!" at i < limit is decided
        i = data.find(b"<!")
        while 0 <= i < limit:
            tail = data[i + 2:i + need]
            if not tail.startswith(_ALLOWED_DECL):
                word = re.match(rb"[A-Za-z]*", tail).group(0).decode("ascii") or "..."
                raise InputError(
                    path, f"line {_line_of(real, base + i)}",
                    f"{what} holds a forbidden XML construct: <!{word} (DTDs and entities are not read)",
                    "remove the <!DOCTYPE ...> / <!ENTITY ...> declarations")
            i = data.find(b"<!", i + 2)
        if not block:
            return
        cut = max(limit, 0)
        carry, base = data[cut:], base + cut
        block = fh.read(_CHUNK)


def _check_head(path: Path, head: bytes, what: str, fix: str) -> None:
    """The start of the file: no UTF-16/32, markup first, an ASCII-compatible encoding."""
    for bom, name in BOMS:
        if head.startswith(bom):
            raise InputError(path, "", f"{what} is {name}-encoded, not UTF-8", "save it as UTF-8")
    body = head.removeprefix(b"\xef\xbb\xbf").lstrip(b" \t\r\n")
    if not body:
        raise InputError(path, "", f"{what} is empty", fix or "pass the full file")
    if not body.startswith(b"<"):
        raise InputError(path, "line 1", f"{what} is not XML (it starts with {body[:8]!r})",
                         fix or "pass an XML file")
    m = _ENCODING.match(body)
    if m is not None and m.group(1).decode("latin-1").lower() not in _ASCII_ENCODINGS:
        raise InputError(path, "line 1", f"{what} declares encoding {short(m.group(1).decode('latin-1'))}",
                         "save it as UTF-8 (encoding=\"UTF-8\")")


def parse_xml_file(path: Path, expected_root: str | None = None, what: str = "route file",
                   fix: str = "") -> Element:
    """Parse an untrusted XML file (:func:`check_xml_file`, then defusedxml: no DTDs, no entity
    expansion); errors are InputErrors."""
    path = Path(path)
    check_xml_file(path, what, fix)
    try:
        root = safe_parse(str(path), forbid_dtd=True).getroot()
    except OSError as err:
        raise unreadable(path, what, fix, err) from None
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
            fix or f"use a leaderboard route file whose root is <{expected_root}>",
        )
    return root


def _float_attr(el: Element, name: str, path: Path, place: str, required: bool) -> float | None:
    """Attribute ``name`` of a waypoint as a float: a finite number within
    :data:`MAX_COORD_M` (x, y, z in m) or :data:`MAX_ANGLE_DEG` (pitch, roll, yaw in degrees)."""
    raw = el.get(name)
    if raw is None:
        if required:
            raise InputError(path, place, f"missing attribute '{name}'", f"add {name}=\"...\"")
        return None
    try:
        value = float(raw)
    except ValueError:
        raise InputError(
            path, place, f"attribute {name}={short(raw)} is not a number", "write a decimal number"
        ) from None
    if not math.isfinite(value):
        raise InputError(path, place, f"attribute {name}={short(raw)} is not finite",
                         "write a finite decimal number")
    bound, unit = (MAX_ANGLE_DEG, "degrees") if name in ("pitch", "roll", "yaw") else (MAX_COORD_M, "m")
    if abs(value) > bound:
        raise InputError(path, place, f"attribute {name}={short(raw)} is out of range "
                         f"(|{name}| > {bound:g} {unit})", "check the value and its units")
    return value


def _parse_route(el: Element, index: int, path: Path) -> RouteSpec:
    rid = el.get("id")
    if rid is None or not rid.strip():
        raise InputError(path, f"route #{index}", "missing attribute 'id'", 'add id="..."')
    place = f"route {rid}" if len(rid) <= 60 else f"route #{index} (id {short(rid)})"
    if len(rid) > 200:
        raise InputError(path, place, f"route id is {len(rid)} characters long", "use an id of at most 200")
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
    town = (el.get("town") or "").strip()
    if len(town) > 100 or town in (".", "..") or any(c in town for c in "/\\\0"):
        raise InputError(path, place, f"town {short(town)} is not a town name",
                         "name a town (such as Town01) without path separators")
    weather_el = el.find("weather")
    weather = tuple(weather_el.attrib.items()) if weather_el is not None else ()
    return RouteSpec(
        id=rid.strip(), town=town, waypoints=tuple(waypoints),
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


def looks_like_path(name: str) -> bool:
    """Whether a suite argument names a file or folder rather than a bundled suite: it has a
    path separator, a suffix (``routes.xml``) or starts with ``.`` or ``~``."""
    return any(c in name for c in "/\\") or name.startswith((".", "~")) or bool(Path(name).suffix)


def suite_file(suite: str, field: object = Field("suite"), folders: bool = False) -> Path | None:
    """The route XML file of ``suite``: a bundled suite's name (``tiny``) or a route file's
    path. With ``folders``, a convert-routes folder (one holding ``index.json``) is accepted
    too, and gives None (its routes are converted already). Otherwise an InputError: a
    path-like name that does not exist is a missing file (named as given), a plain name no
    bundled suite has is an unknown suite, with the closest names (``field`` names the
    argument)."""
    from icrsumo.core.resources import bundled_suites

    suites = bundled_suites()
    path = Path(suite).expanduser()
    if folders and (path / "index.json").is_file():
        return None
    if suite in suites:
        return suites[suite]
    if path.is_file():
        return path
    kinds = "a route XML file or a convert-routes folder" if folders else "a route XML file"
    if path.is_dir():
        raise InputError(path, "", "is a folder without index.json, not a convert-routes folder" if folders
                         else "is a folder, not a route XML file", f"give {kinds}")
    if looks_like_path(suite):
        raise InputError(path if suite.startswith("~") else suite, "", "no such route file",
                         f"check the path; or give a bundled suite: {', '.join(suites)}")
    hint = _did_you_mean(suite, list(suites), cutoff=0.5)
    raise InputError(field, suite, "unknown suite",
                     f"{hint}use a bundled suite ({', '.join(suites)}) or {kinds}")


def route_ids(path: Path) -> list[str]:
    """The id of every ``<route>`` of a route file, in file order, read without converting
    anything (a route that is otherwise malformed keeps its id here; :func:`read_routes` names
    its problem)."""
    root = parse_xml_file(Path(path), expected_root="routes")
    return [rid.strip() for rid in (el.get("id") for el in root.findall("route")) if rid and rid.strip()]


def _did_you_mean(name: str, names: list[str], cutoff: float) -> str:
    """"did you mean A, B or C? " for the names closest to ``name`` ("" when none is close)."""
    close = difflib.get_close_matches(name, names, n=3, cutoff=cutoff)
    if not close:
        return ""
    return f"did you mean {' or '.join([', '.join(close[:-1]), close[-1]] if len(close) > 1 else close)}? "


def check_route_selection(selected: Iterable[str], ids: Iterable[str], field: Field, suite: str) -> None:
    """InputError for the first of the ``selected`` route ids that is not among ``ids`` (the
    route file's, :func:`route_ids`), naming its closest ids and the suite's first ids."""
    have = list(ids)
    known = set(have)
    for rid in selected:
        if rid in known:
            continue
        hint = _did_you_mean(rid, have, cutoff=0.6)
        shown = ", ".join(have[:4]) + (f", ... ({len(have)} routes)" if len(have) > 4 else "")
        raise InputError(field, short(rid, 60), f"no such route in the suite {suite}",
                         f"{hint}use the suite's route ids: {shown}")


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
