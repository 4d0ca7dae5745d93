"""icrsumo list: what exists, printed from the code's own registries (nothing typed twice)."""

from __future__ import annotations

import pytest

from icrsumo.agents.registry import DEFAULT_AGENT, REGISTRY
from icrsumo.app.cli.main import main
from icrsumo.core.resources import bundled_suites
from icrsumo.core.vocab import ALL_FAMILIES, CONTROL_FAMILIES, DELIVERY_FAMILIES, FAMILY_DESCRIPTIONS, Family


def _lines(capsys, *argv):
    assert main(["list", *argv]) == 0
    return capsys.readouterr().out.splitlines()


def test_suites_agents_and_families_come_from_the_registries(capsys):
    assert [ln.split()[0] for ln in _lines(capsys, "suites")] == list(bundled_suites())
    agents = _lines(capsys, "agents")
    assert [ln.split()[0] for ln in agents] == list(REGISTRY)
    assert [ln.split()[0] for ln in agents if ln.endswith("(default)")] == [DEFAULT_AGENT]
    assert [ln.split()[0] for ln in _lines(capsys, "families")] == [f.value for f in ALL_FAMILIES]
    from icrsumo.guards.registry import GUARDS

    assert [ln.split()[0] for ln in _lines(capsys, "guards")] == [*GUARDS, "llm:MODEL@URL"]


def test_each_family_is_listed_once_with_its_kind_and_description(capsys):
    for line in _lines(capsys, "families"):
        name, kind, description = line.split(maxsplit=2)
        assert kind == ("control" if Family(name) in CONTROL_FAMILIES else
                        "delivery" if Family(name) in DELIVERY_FAMILIES else "default")
        assert description == FAMILY_DESCRIPTIONS[Family(name)] and "control" not in description


def test_routes_of_a_suite(capsys):
    rows = _lines(capsys, "routes", "--suite", "langauto-tiny")
    assert len(rows) == 16 and all(r.split()[1].startswith("Town") for r in rows)


@pytest.mark.parametrize("argv, expect", [(["routes", "--suite", "huge"], "--suite: huge: unknown suite"),
                                          (["routes", "--suite", "huge.xml"], "huge.xml: no such route file"),
                                          (["colours"], "invalid choice: 'colours'")])
def test_bad_input_is_one_line(capsys, argv, expect):
    assert main(["list", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expect in err[0]
