"""Where bundled data (networks, route suites, template banks) and SUMO's tools live."""

from __future__ import annotations

import os
from functools import cache
from pathlib import Path

_PKG = Path(__file__).resolve().parents[1]  # the icrsumo package


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
    """Bundled town name -> its ``.net.xml`` path: icrsumo's own towns (``networks/``) and
    CARLA's LangAuto towns ``Town01`` ... ``Town10HD`` (``networks/carla/``)."""
    root = data_dir("networks")
    files = sorted(root.glob("*.net.xml")) + sorted(root.glob("*/*.net.xml"))
    return {p.name[: -len(".net.xml")]: p for p in files}


def bundled_suites() -> dict[str, Path]:
    """Bundled route suite name -> its route XML path: icrsumo's splits (tiny, short, long,
    train: ``routes/``), LangAuto's tracks (langauto-tiny, langauto-short, langauto-long:
    ``routes/langauto/``) and icrsumo's training routes on CARLA's towns (carla-train:
    ``routes/carla-train/``; carla-focus: ``routes/carla-focus/``)."""
    root = data_dir("routes")
    files = sorted(root.glob("*.xml")) + sorted(root.glob("*/*.xml"))
    return {p.stem: p for p in files}


def suite_coords(suite: str) -> str | None:
    """The coordinate frame (``sumo`` or ``carla``) of a bundled suite's route file, from the
    ``suite.json`` beside it (``None``: not a bundled suite, or no frame recorded)."""
    from .errors import InputError
    from .fsio import read_json

    path = bundled_suites().get(suite)
    meta = path.parent / "suite.json" if path is not None else None
    if meta is None or not meta.is_file():
        return "sumo" if path is not None else None
    doc = read_json(meta, "suite description", "reinstall icrsumo")
    coords = doc.get("coords", "sumo") if isinstance(doc, dict) else None
    if coords not in ("sumo", "carla"):
        from .errors import short

        raise InputError(meta, "coords", f"must be \"sumo\" or \"carla\", not {short(coords)}",
                         "reinstall icrsumo")
    return coords


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
