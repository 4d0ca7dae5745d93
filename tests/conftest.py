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


@pytest.fixture(scope="session")
def converted(tmp_path_factory) -> dict[str, Path]:
    """Every bundled evaluation split converted once per session (2 workers)."""
    from icrsumo.convert import ConvertOptions, convert_routes
    from icrsumo.resources import bundled_suites

    out = {}
    for split in ("tiny", "short", "long"):
        d = tmp_path_factory.mktemp(split)
        rep = convert_routes(bundled_suites()[split], d, ConvertOptions(workers=2))
        assert rep.failures == []
        out[split] = d
    return out


@pytest.fixture(scope="session")
def generated(converted, tmp_path_factory) -> dict[str, Path]:
    from icrsumo.instructions.generate import GenerateOptions, generate

    out = {}
    for split, d in converted.items():
        o = tmp_path_factory.mktemp(f"instr_{split}")
        written, failures = generate(d, o, GenerateOptions(workers=2))
        assert failures == []
        out[split] = o
    return out
