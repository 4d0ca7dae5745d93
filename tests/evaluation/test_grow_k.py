"""A larger --k in an existing out folder adds the missing variants: the stored episodes and
their instruction sequences stay, only the new variants run, and growing is deterministic."""

from __future__ import annotations

import json

import pytest

from icrsumo.app.cli.main import main
from icrsumo.instructions.store import read_instruction_sets

pytestmark = pytest.mark.sumo

RUN = ["evaluate", "--suite", "tiny", "--routes", "tiny_003", "--agent", "instruction-follower",
       "--family", "misleading", "--family", "noise", "--workers", "1", "--quiet"]


def _sets(out):
    return {(s.family, s.k): s for s in read_instruction_sets(out / "instructions" / "tiny_003.json")}


def test_a_larger_k_adds_the_missing_variants(tmp_path, capsys):
    out = tmp_path / "out"
    assert main([*RUN, "--k", "1", "--out", str(out)]) == 0
    before = _sets(out)
    assert "3 episodes done" in capsys.readouterr().err
    assert main([*RUN, "--k", "3", "--out", str(out)]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    # the run says what it ran now (4 new variants) beside what was stored; the digest stays last
    assert err[-2].startswith("4 episodes run now, 3 already stored; 7 episodes done, 0 crashed")
    assert err[-1].startswith("digest: sha256:")
    after = _sets(out)
    assert all(after[key] == before[key] for key in before)  # every earlier sequence kept as it was
    for fam in ("misleading", "noise"):
        for idx in range(len(after[(fam, 0)].instructions)):
            used = [after[(fam, k)].instructions[idx].template for k in range(3)]
            if "keep" not in used:
                assert len(set(used)) == 3, used  # the new variants drew templates not used before
    config = json.loads((out / "config.json").read_text())
    assert config["k"] == 3 and config["k_grown_from"] == [1]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["k"] == 3 and summary["agents"]["instruction-follower"]["families"]["noise"]["n"] == 3

    again = tmp_path / "again"  # the same growth elsewhere: the same files, byte for byte
    assert main([*RUN, "--k", "1", "--out", str(again)]) == 0
    assert main([*RUN, "--k", "3", "--out", str(again)]) == 0
    for name in ("instructions/tiny_003.json", "config.json", "summary.json", "results.md"):
        assert (again / name).read_bytes() == (out / name).read_bytes(), name

    capsys.readouterr()
    assert main([*RUN, "--k", "2", "--out", str(out)]) == 2  # smaller: refused, one line
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "k=3 (now 2)" in err[0] and "use --k 3 or more" in err[0]
