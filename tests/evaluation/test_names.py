"""Agent names are text a user chooses: an over-long one is refused before any episode runs
(and one already in a store still gets its reports: file names made of names are bounded), and
one with a ``|`` or terminal escape sequences stays in its table cell and never reaches the
terminal raw (Markdown, LaTeX and terminal each escape it their way)."""

from __future__ import annotations

import re
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from icrsumo.core.fsio import MAX_FILE_NAME

pytestmark = pytest.mark.sumo

AGENT = '''
import numpy as np
from icrsumo.agents.base import Action

class Named:
    name = {name!r}
    privileged = False
    def reset(self, info):
        pass
    def act(self, obs):
        return Action(waypoints=np.array([[2.5, 0.0], [5.0, 0.0], [7.5, 0.0]]), target_speed=5.0)
'''
#: a pipe, a clipboard write (OSC 52), a bell and a screen clear
HOSTILE = "a|b\x1b]52;c;aGVsbG8=\x07\x1b[2J"
RUN = ["evaluate", "--suite", "tiny", "--routes", "tiny_003", "--family", "paraphrase", "--k", "1",
       "--workers", "1"]


def _agent(folder: Path, name: str) -> str:
    path = folder / "named.py"
    path.write_text(AGENT.format(name=name))
    return f"{path}:Named"


def _icrsumo(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "icrsumo", *args], capture_output=True, text=True,
                          timeout=600)


@pytest.fixture(scope="module")
def hostile(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    """An evaluation (not quiet: the table is printed) of an agent named :data:`HOSTILE`."""
    tmp = tmp_path_factory.mktemp("names")
    out = tmp / "out"
    p = _icrsumo(*RUN, "--agent", _agent(tmp, HOSTILE), "--out", str(out))
    assert p.returncode == 0, p.stderr
    return out, p


def _first_table(text: str) -> list[str]:
    lines = text.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("|"))
    end = next((i for i in range(start, len(lines)) if not lines[i].startswith("|")), len(lines))
    return lines[start:end]


def _cells(line: str) -> int:
    return len(re.split(r"(?<!\\)\|", line.strip().strip("|")))


def test_a_hostile_name_stays_in_its_cells_and_off_the_terminal(hostile):
    out, p = hostile
    for stream in (p.stdout, p.stderr):
        assert "\x1b" not in stream and "\x07" not in stream
    assert "a\\|b\\x1b]52;c;aGVsbG8=\\x07\\x1b[2J" in p.stdout            # shown, written out
    for name in ("results.md", "statistics.md", "attribution.md"):
        table = _first_table((out / name).read_text())
        assert len(table) > 2 and all(_cells(ln) == _cells(table[0]) for ln in table), name
        assert not re.search(r"[\x00-\x08\x0b-\x1f\x7f]", (out / name).read_text()), name
    tex = (out / "results.tex").read_text()
    assert not re.search(r"[\x00-\x08\x0b-\x1f\x7f]", tex)
    assert "a|b\\textbackslash{}x1b]52;c;aGVsbG8=\\textbackslash{}x07" in tex


def test_an_over_long_name_is_refused_before_anything_runs(tmp_path):
    out = tmp_path / "out"
    p = _icrsumo(*RUN, "--quiet", "--agent", _agent(tmp_path, "n" * 300), "--out", str(out))
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(lines) == 1 and "Traceback" not in p.stderr, p.stderr
    assert "agent: " in lines[0] and "is 300 characters long (at most 200)" in lines[0]
    assert "shorter name" in lines[0] and not out.exists()


def test_a_store_holding_an_over_long_name_is_still_reported(hostile, tmp_path):
    """Episodes stored under a 300-character name (by an icrsumo that did not refuse it) get
    their reports: the files named after it are cut to a bounded length and end with a hash."""
    out = Path(shutil.copytree(hostile[0], tmp_path / "out"))
    long = "x" * 300
    db = sqlite3.connect(out / "results.sqlite")
    with db:
        db.execute("UPDATE episodes SET agent = ?", (long,))
    db.close()
    p = _icrsumo("report", str(out), "--quiet")
    assert p.returncode == 0, p.stderr
    files = sorted(f.name for f in (out / "leaderboard").iterdir() if f.name.startswith("x"))
    assert len(files) == 2 and all(len(f) <= MAX_FILE_NAME + len("_paraphrase.json") for f in files)
    assert all(f.startswith("x" * 40) and re.search(r"-[0-9a-f]{8}_", f) for f in files)
    assert (out / "figures" / f"confusion_{files[0].partition('_')[0]}.png").is_file()
