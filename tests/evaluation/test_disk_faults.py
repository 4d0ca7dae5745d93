"""Full disks and vanished folders, for real: a tmpfs filled to the brim (where the test may
mount one) and an out folder deleted while a run goes. The errors name the real cause, never
call a healthy store damaged or suggest throwing it away, and never count an environment fault
as an agent's crash."""

from __future__ import annotations

import os
import shutil
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.sumo

ARGS = ["--agent", "instruction-follower", "--family", "paraphrase", "--routes", "tiny_000,tiny_001",
        "--workers", "2", "--quiet"]


def _run(out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "icrsumo", "evaluate", *ARGS, *extra, "--out", str(out)],
                          capture_output=True, text=True, timeout=600)


@pytest.fixture
def small_disk(tmp_path):
    """A 40 MiB tmpfs (skipped where this process may not mount one)."""
    mnt = tmp_path / "disk"
    mnt.mkdir()
    try:
        mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=40m", "tmpfs", str(mnt)],
                                 capture_output=True).returncode == 0
    except OSError:   # no mount command
        mounted = False
    if not mounted:
        pytest.skip("cannot mount a tmpfs here (needs root and CAP_SYS_ADMIN)")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def _fill(mnt: Path, leave: int) -> Path:
    st = os.statvfs(mnt)
    filler = mnt / "filler"
    filler.write_bytes(b"\0" * max(0, st.f_bavail * st.f_frsize - leave))
    return filler


def test_a_full_disk_is_named_as_such_and_the_store_survives(small_disk, tmp_path):
    out = small_disk / "o"
    first = _run(out, "--k", "1")
    assert first.returncode == 0, first.stderr
    filler = _fill(small_disk, 40 << 10)
    grown = _run(out, "--k", "2")                       # more episodes to store: no room
    assert grown.returncode == 2 and len(grown.stderr.strip().splitlines()) == 1, grown.stderr
    assert "no space left" in grown.stderr and "damaged" not in grown.stderr
    assert "move it away" not in grown.stderr
    cmd = [sys.executable, "-m", "icrsumo", "convert-routes", "routes/tiny.xml", "--out",
           str(small_disk / "c")]
    conv = subprocess.run(cmd, capture_output=True, text=True, cwd=Path(__file__).parents[2])
    assert conv.returncode == 2 and "no space left" in conv.stderr
    assert "a folder where a file" not in conv.stderr
    filler.unlink()
    again = _run(out, "--k", "2")                       # room again: it resumes
    assert again.returncode == 0, again.stderr
    with sqlite3.connect(out / "results.sqlite") as c:
        assert c.execute("SELECT COUNT(*) FROM episodes WHERE status = 'done'").fetchone()[0] == 2 * 3


def test_an_out_folder_deleted_mid_run_is_an_error_not_agent_crashes(tmp_path):
    out = tmp_path / "o"
    cmd = [sys.executable, "-m", "icrsumo", "evaluate", *ARGS, "--k", "6", "--out", str(out)]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        try:
            with sqlite3.connect(out / "results.sqlite") as c:
                if c.execute("SELECT COUNT(*) FROM episodes").fetchone()[0] >= 1:
                    break
        except sqlite3.Error:
            pass
        assert p.poll() is None, p.stderr.read()
        time.sleep(0.2)
    shutil.rmtree(out)
    assert p.wait(timeout=120) == 2
    err = p.stderr.read()
    assert "was deleted while the run was going" in err and "crashed" not in err
