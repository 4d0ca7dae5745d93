"""Golden outputs: the main job (``icrsumo evaluate --family misleading`` on the bundled
defaults) and ``icrsumo report`` on a LangAuto-tiny folder give, file for file, the bytes
committed under tests/data/golden (written before the package was reorganised, issue 44): a
change of code that is meant to change no behaviour must leave every one of them the same.

The stored rows are compared column by column (each episode's log by its SHA-256), all but
``fingerprint``: an agent's fingerprint covers the modules it reaches by their names
(docs/results.md), so moving a module changes it by design. Figures (PNG) are left out: their
bytes depend on the matplotlib build.

``ICRSUMO_UPDATE_GOLDEN=1 python -m pytest tests/test_golden.py`` writes the files anew (only
for a change that is meant to change results; say why in the commit)."""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.sumo

GOLDEN = Path(__file__).resolve().parent / "data" / "golden"
README = Path(__file__).resolve().parents[1] / "README.md"
UPDATE = os.environ.get("ICRSUMO_UPDATE_GOLDEN") == "1"
#: the outputs compared byte for byte (relative to the out folder); leaderboard/ whole
TEXT_FILES = ("episodes.csv", "summary.json", "results.md", "results.csv", "results.tex",
              "statistics.md", "statistics.csv", "attribution.md", "attribution.json")


def _icrsumo(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, "-m", "icrsumo", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc


def _rows(out: Path) -> str:
    """The stored episodes, one JSON line each (sorted by key), the log by its SHA-256 and
    without ``fingerprint``."""
    with sqlite3.connect(f"file:{out / 'results.sqlite'}?mode=ro", uri=True) as c:
        c.row_factory = sqlite3.Row
        rows = c.execute("SELECT * FROM episodes ORDER BY agent, route_id, family, k, seed").fetchall()
    lines = []
    for r in rows:
        d = {k: r[k] for k in r.keys() if k not in ("fingerprint", "log")}  # noqa: SIM118 - a Row iterates values
        d["log_sha256"] = hashlib.sha256(r["log"] or b"").hexdigest()
        lines.append(json.dumps(d, sort_keys=True))
    return "\n".join(lines) + "\n"


def _outputs(out: Path) -> dict[str, bytes]:
    files = {name: (out / name).read_bytes() for name in TEXT_FILES if (out / name).is_file()}
    for p in sorted((out / "leaderboard").rglob("*")):
        if p.is_file():
            files[p.relative_to(out).as_posix()] = p.read_bytes()
    files["results.sqlite.rows.jsonl"] = _rows(out).encode()
    return files


def _check(name: str, files: dict[str, bytes]) -> None:
    folder = GOLDEN / name
    if UPDATE:
        shutil.rmtree(folder, ignore_errors=True)
        for rel, data in files.items():
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            (folder / rel).write_bytes(data)
        return
    want = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())
    assert sorted(files) == want, f"{name}: other files than the golden ones"
    for rel in want:
        assert files[rel] == (folder / rel).read_bytes(), f"{name}/{rel} differs from tests/data/golden"


def test_the_main_job_gives_the_golden_outputs_and_the_readme_digest(converted, tmp_path):
    shutil.copytree(converted["tiny"], tmp_path / "icr_out" / "scenarios")
    proc = _icrsumo("evaluate", "--family", "misleading", "--quiet", cwd=tmp_path)
    digest = re.search(r"digest: (sha256:[0-9a-f]{64})", proc.stderr)
    assert digest and f"`{digest.group(1)}`" in README.read_text(encoding="utf-8"), proc.stderr[-600:]
    _check("main_job", _outputs(tmp_path / "icr_out"))


def test_report_on_a_langauto_tiny_folder_gives_the_golden_outputs(tmp_path):
    out = tmp_path / "lt"
    _icrsumo("evaluate", "--suite", "langauto-tiny", "--agent", "bev-ngram-aug", "--agent",
             "instruction-follower", "--family", "misleading,noise", "--k", "1", "--workers", "2",
             "--quiet", "--out", str(out), cwd=tmp_path)
    for name in (*TEXT_FILES, "leaderboard"):  # report writes them all again from the store
        p = out / name
        shutil.rmtree(p) if p.is_dir() else p.unlink(missing_ok=True)
    _icrsumo("report", str(out), cwd=tmp_path)
    _check("langauto_tiny_report", _outputs(out))
