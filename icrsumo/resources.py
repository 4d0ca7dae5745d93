"""Where bundled data (networks, route suites, template banks) and SUMO's tools live."""

from __future__ import annotations

import os
from functools import cache
from pathlib import Path

_PKG = Path(__file__).resolve().parent


def data_dir(name: str) -> Path:
    """Folder of bundled data ``name`` (networks, routes, templates).

    In a wheel the folders ship as ``icrsumo/_data/<name>``; in a source checkout (editable
    install) they are the repository's top-level folders.
    """
    for candidate in (_PKG / "_data" / name, _PKG.parent / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"bundled data folder {name!r} is missing from the installation")


def bundled_towns() -> dict[str, Path]:
    """Bundled town name -> its ``.net.xml`` path."""
    return {
        p.name[: -len(".net.xml")]: p for p in sorted(data_dir("networks").glob("*.net.xml"))
    }


def bundled_suites() -> dict[str, Path]:
    """Bundled route split name (tiny, short, long, train) -> its route XML path."""
    return {p.stem: p for p in sorted(data_dir("routes").glob("*.xml"))}


@cache
def sumo_home() -> Path:
    """SUMO's home folder (``bin/`` and ``tools/``) from the eclipse-sumo wheel.

    Sets ``SUMO_HOME`` for child processes and for libsumo, which otherwise points at a folder
    without ``tools/`` and ``bin/``.
    """
    import sumo  # the eclipse-sumo wheel; light import

    home = Path(sumo.SUMO_HOME)
    os.environ["SUMO_HOME"] = str(home)
    return home


def sumo_binary(name: str) -> str:
    """Path of a SUMO executable such as ``netconvert`` or ``duarouter``."""
    return str(sumo_home() / "bin" / name)


def sumo_tool(name: str) -> str:
    """Path of a SUMO Python tool such as ``randomTrips.py``."""
    return str(sumo_home() / "tools" / name)
