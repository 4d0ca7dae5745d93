"""An out folder is one command's, used by one process at a time, and read where it cannot be
written: a report refuses a folder a run still owns (never a summary of half its episodes), a
read-only folder is said to be read-only (never "damaged"), and an evaluate folder and an attack
folder are refused to each other (config.json records which command made it)."""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.sumo

SMALL = ["--suite", "tiny", "--routes", "tiny_003", "--agent", "route-oracle", "--workers", "1", "--quiet"]


def _icrsumo(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "icrsumo", *args], capture_output=True, text=True,
                          timeout=600, **kw)


def _one_line(p: subprocess.CompletedProcess) -> str:
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(lines) == 1 and "Traceback" not in p.stderr, p.stderr
    return lines[0]


def _files(out: Path) -> dict[Path, bytes]:
    return {p: p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    """An evaluate folder: route-oracle on tiny_003, baseline and one paraphrase (2 episodes)."""
    out = tmp_path_factory.mktemp("safety") / "base"
    p = _icrsumo("evaluate", *SMALL, "--family", "paraphrase", "--k", "1", "--out", str(out))
    assert p.returncode == 0, p.stderr
    return out


@pytest.fixture
def folder(base, tmp_path) -> Path:
    """A copy of the evaluate folder, for one test to change."""
    return Path(shutil.copytree(base, tmp_path / "out"))


def test_report_refuses_a_folder_that_another_run_owns(folder):
    """A report while an evaluation of the folder still runs (holding its lock) is refused in one
    line and writes nothing; once the run has ended, it goes."""
    holder = subprocess.Popen(
        [sys.executable, "-c", "import fcntl, os, sys\n"
         "fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT)\n"
         "fcntl.flock(fd, fcntl.LOCK_EX)\nos.write(fd, str(os.getpid()).encode())\n"
         "print('held', flush=True)\nsys.stdin.read()\n", str(folder / ".icrsumo.lock")],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        (folder / "summary.json").unlink()
        before = _files(folder)
        line = _one_line(_icrsumo("report", str(folder), "--quiet"))
        assert f"another icrsumo run (pid {holder.pid}) is using this folder" in line
        assert "report again" in line
        assert _files(folder) == before and not (folder / "summary.json").exists()
    finally:
        holder.stdin.close()
        holder.wait(timeout=30)
    p = _icrsumo("report", str(folder), "--quiet")
    assert p.returncode == 0, p.stderr
    assert (folder / "summary.json").is_file() and not (folder / ".icrsumo.lock").exists()


@contextlib.contextmanager
def read_only(path: Path):
    """``path`` read-only for this process and its children: permissions for a user, a
    read-only bind mount for root (whom permissions do not stop); skipped where neither works."""
    if os.geteuid() != 0:
        modes = {p: p.stat().st_mode for p in [path, *path.rglob("*")]}
        for p in modes:
            p.chmod(0o555 if p.is_dir() else 0o444)
        try:
            yield
        finally:
            for p, mode in modes.items():
                p.chmod(mode)
        return
    bind = subprocess.run(["mount", "--bind", str(path), str(path)], capture_output=True)
    if bind.returncode != 0:
        pytest.skip("root, and no bind mount here: a read-only folder cannot be made")
    try:
        ro = subprocess.run(["mount", "-o", "remount,ro,bind", str(path)], capture_output=True)
        if ro.returncode != 0:
            pytest.skip("root, and the bind mount cannot be made read-only here")
        yield
    finally:
        subprocess.run(["umount", str(path)], capture_output=True)


def test_a_read_only_folder_is_named_as_such_and_still_shown(folder, tmp_path):
    with read_only(folder):
        assert not os.access(folder, os.W_OK)
        line = _one_line(_icrsumo("report", str(folder), "--quiet"))
        assert "the folder is not writable" in line and "copy it somewhere writable" in line
        assert "damaged" not in line and "move it away" not in line
        line = _one_line(_icrsumo("show", str(folder), "--agent", "route-oracle", "--route", "tiny_003"))
        assert "not writable" in line and "--dir" in line and "damaged" not in line
        shown = _icrsumo("show", str(folder), "--agent", "route-oracle", "--route", "tiny_003",
                         "--dir", str(tmp_path / "watch"))
        assert shown.returncode == 0, shown.stderr
        assert "the replay reproduces the stored log byte for byte" in shown.stdout
        digest = _icrsumo("digest", str(folder))
        assert digest.returncode == 0 and "summary.json holds the same digest" in digest.stderr, digest.stderr


def test_an_attack_is_refused_an_evaluate_folder(folder):
    before = _files(folder)
    line = _one_line(_icrsumo("attack", *SMALL, "--budget", "1", "--out", str(folder)))
    assert f"{folder / 'config.json'}: run: the folder holds the results of an evaluate run" in line
    assert "give the attack run another out folder" in line
    assert _files(folder) == before


def test_an_evaluate_is_refused_an_attack_folder_which_still_resumes(tmp_path):
    out = tmp_path / "attack"
    first = _icrsumo("attack", *SMALL, "--budget", "1", "--out", str(out))
    assert first.returncode == 0, first.stderr
    before = _files(out)
    line = _one_line(_icrsumo("evaluate", *SMALL, "--family", "paraphrase", "--k", "2", "--out", str(out)))
    assert "the folder holds the results of an attack run" in line and "config.json" in line
    assert "give the evaluate run another out folder" in line
    line = _one_line(_icrsumo("attack", *SMALL, "--budget", "1", "--constraint", "misleading",
                              "--out", str(out)))
    assert "config.json: constraint: " in line and "constraint='goal' (now 'misleading')" in line
    assert _files(out) == before
    again = _icrsumo("attack", *SMALL, "--budget", "1", "--out", str(out))  # the attack resumes
    assert again.returncode == 0, again.stderr
