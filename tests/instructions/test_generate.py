"""icrsumo generate: byte-identical output, worker counts, CLI errors."""

from __future__ import annotations

import json
import shutil

from icrsumo.app.cli.main import main
from icrsumo.core.resources import data_dir


def _tree(root):
    return {p.name: p.read_bytes() for p in sorted(root.glob("*.json"))}


def test_generate_is_byte_identical_across_runs_and_workers(converted, generated, tmp_path, capsys):
    code = main(["generate", str(converted["tiny"]), "--out", str(tmp_path / "a"), "--workers", "1"])
    assert code == 0
    assert _tree(tmp_path / "a") == _tree(generated["tiny"])
    index = json.loads((tmp_path / "a" / "index.json").read_text())
    assert len(index["routes"]) == 16 and index["failures"] == []


def test_subset_of_families_and_k(converted, generated, tmp_path):
    code = main(["generate", str(converted["tiny"]), "--out", str(tmp_path / "b"), "--families",
                 "misleading,noise", "--k", "3", "--seed", "7"])
    assert code == 0
    doc = json.loads(next(p for p in (tmp_path / "b").glob("*.json") if p.name != "index.json").read_text())
    assert [(s["family"], s["k"]) for s in doc["sets"]] == [
        ("baseline", 0), ("misleading", 0), ("misleading", 1), ("misleading", 2),
        ("noise", 0), ("noise", 1), ("noise", 2)]


def test_cli_errors_are_one_line(converted, tmp_path, capsys):
    assert main(["generate", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert "no converted scenarios found" in capsys.readouterr().err
    assert main(["generate", str(converted["tiny"]), "--out", str(tmp_path / "o"), "--families",
                 "sarcasm"]) == 2
    assert "unknown family sarcasm" in capsys.readouterr().err
    banks = tmp_path / "banks"
    shutil.copytree(data_dir("templates"), banks)
    p = banks / "paraphrase.json"
    data = json.loads(p.read_text())
    data["intents"]["right"]["plain"][5]["text"] = "Go left at {junction}."
    p.write_text(json.dumps(data))
    assert main(["generate", str(converted["tiny"]), "--out", str(tmp_path / "o"), "--templates",
                 str(banks)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "paraphrase.json: intents.right.plain[5]" in err[0]
    assert not (tmp_path / "o").exists()
