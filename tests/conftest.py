"""Shared fixtures: paths to test data and a converted copy of the CARLA-style fixture."""

from __future__ import annotations

from pathlib import Path

import pytest

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA


@pytest.fixture(scope="session")
def carla_mini_out(tmp_path_factory) -> Path:
    """carla_mini_routes.xml converted via --xodr --coords carla (converted once per session)."""
    from icrsumo.convert import ConvertOptions, convert_routes

    out = tmp_path_factory.mktemp("carla_mini")
    report = convert_routes(
        DATA / "carla_mini_routes.xml", out,
        ConvertOptions(coords="carla", xodr=DATA / "carla_mini.xodr", workers=2),
    )
    assert report.failures == []
    return out
