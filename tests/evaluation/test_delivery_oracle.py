"""The simulation adds nothing to the delivery families: the route-oracle, which ignores
language, scores every variant exactly as its baseline (issue 45)."""

from __future__ import annotations

import json
import sqlite3

import pytest

import icrsumo
from icrsumo.core.vocab import DELIVERY_FAMILIES
from icrsumo.instructions.store import skipped_families
from icrsumo.results.summary import Summary

pytestmark = pytest.mark.sumo


def test_the_route_oracle_loses_nothing_to_when_and_how_instructions_come(converted, tmp_path, capsys):
    out = tmp_path / "o"
    icrsumo.evaluate(suite=converted["tiny"], agents="route-oracle", families=list(DELIVERY_FAMILIES),
                     k=2, workers=2, out=out)
    err = capsys.readouterr().err
    fams = Summary.read(out / "summary.json").agents["route-oracle"].families  # as written and read back
    assert list(fams) == list(DELIVERY_FAMILIES)
    for fam, row in fams.items():
        assert (row.d_ds, row.d_rc, row.d_is) == (0.0, 0.0, 0.0), fam
        assert row.n > 0 and row.n_crashed == 0 and row.unpaired == 0
        assert row.decisions.decisions["followed_route"] > 0 and row.decisions.adherence == 1.0
    # a family a route cannot carry: named once, no episodes there, counted in the summary
    skipped = skipped_families(out / "instructions")
    assert skipped and all(f"route {rid}: family {fam} cannot be built" in err
                           for rid, fs in skipped.items() for fam in fs)
    with sqlite3.connect(out / "results.sqlite") as db:
        stored = set(db.execute("SELECT route_id, family FROM episodes").fetchall())
    assert not {(rid, fam) for rid, fs in skipped.items() for fam in fs} & stored
    doc = json.loads((out / "summary.json").read_text())["agents"]["route-oracle"]["families"]
    for fam in DELIVERY_FAMILIES:
        n = sum(fam in fs for fs in skipped.values())
        assert fams[fam].skipped_routes == n and doc[fam].get("skipped_routes", 0) == n
        assert fams[fam].n_routes + n == 16
