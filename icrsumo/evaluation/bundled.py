"""The bundled-suite pipeline: one route of a bundled suite, converted and its instructions
generated on first use into a cache folder.

Used by the Gymnasium environment (:mod:`icrsumo.app.env`) and ``icrsumo check-agent``, which need
a runnable scenario without an ``icrsumo evaluate`` out folder. The conversion and generation
are the protocol's own (``convert-routes`` and ``generate`` with default options: traffic
seed 0, variant seed 2026, K = 8), one route per folder, so the episode is the one
``icrsumo evaluate`` runs for that route. The cache lives in ``$ICRSUMO_CACHE``, else
``$XDG_CACHE_HOME/icrsumo``, else ``~/.cache/icrsumo``; deleting it is always safe.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from icrsumo.core.defaults import DEFAULT_SUITE
from icrsumo.core.errors import InputError
from icrsumo.core.fsio import write_atomic
from icrsumo.core.resources import bundled_suites, suite_coords
from icrsumo.instructions.baseline import LAYOUT_VERSION
from icrsumo.instructions.generate import GenerateOptions, generate
from icrsumo.world.convert import CONVERTER_VERSION, ConvertOptions, convert_routes, safe_name
from icrsumo.world.routes import format_routes, read_routes

#: the route the environment and check-agent use by default: 78 m in icr_grid, one left turn
DEFAULT_ROUTE = "tiny_003"


def cache_root() -> Path:
    """The cache folder (not created here)."""
    if os.environ.get("ICRSUMO_CACHE"):
        return Path(os.environ["ICRSUMO_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "icrsumo"


def bundled_route(route: str = DEFAULT_ROUTE, suite: str = DEFAULT_SUITE,
                  traffic: str = "normal") -> tuple[Path, Path]:
    """(scenario folder, instruction file) of bundled route ``route`` of split ``suite``,
    converted and generated into the cache on first use (a few seconds; later calls only
    check that the files exist). Safe to call from several processes at once (file lock)."""
    suites = bundled_suites()
    if suite not in suites:
        raise InputError("suite", suite, "not a bundled route split", f"use one of {', '.join(suites)}")
    # the converter's and the instruction layout's versions in the path: a route converted or
    # instructed by an earlier icrsumo (other traffic, other triggers) is never reused
    root = cache_root() / f"{suite}-{traffic}-c{CONVERTER_VERSION}-l{LAYOUT_VERSION}" / safe_name(route)
    sc_dir = root / "scenarios" / safe_name(route)
    instr = root / "instructions" / f"{safe_name(route)}.json"
    if (sc_dir / "scenario.json").is_file() and instr.is_file():
        return sc_dir, instr
    specs, _ = read_routes(suites[suite])
    spec = next((s for s in specs if s.id == route), None)
    if spec is None:
        ids = [s.id for s in specs]
        raise InputError(suites[suite], f"route {route}", "no such route in the split",
                         f"use one of {ids[0]} ... {ids[-1]}")
    root.mkdir(parents=True, exist_ok=True)
    with open(root / ".lock", "w") as lock:
        with contextlib.suppress(ImportError):  # POSIX: another process may be converting this route
            import fcntl

            fcntl.flock(lock, fcntl.LOCK_EX)
        if not (sc_dir / "scenario.json").is_file():
            routes_file = root / "route.xml"
            write_atomic(routes_file, format_routes([spec]))
            report = convert_routes(routes_file, root, ConvertOptions(coords=suite_coords(suite) or "sumo",
                                                                      traffic=traffic, workers=1))
            if report.failures:
                raise InputError(suites[suite], f"route {route}", f"conversion failed: {report.failures[0]}",
                                 "report this as a bug")
        if not instr.is_file():
            _, failures = generate(sc_dir, instr.parent, GenerateOptions(workers=1))
            if failures:
                raise InputError(suites[suite], f"route {route}", f"generation failed: {failures[0]}",
                                 "report this as a bug")
    return sc_dir, instr
