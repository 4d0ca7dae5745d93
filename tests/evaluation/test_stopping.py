"""How a run ends and who owns a folder, with real processes: SIGTERM / SIGHUP stop the run as
Ctrl-C does (exit 128 + signal, workers gone, the store consistent, a rerun resumes to the same
result as a fresh run), kill -9 of the main process takes its workers with it, and two runs
started together on one folder: one runs, the other is refused."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.sumo

#: the instruction-follower, held at its next decision while the file $ICRSUMO_TEST_HOLD exists
#: (at most 120 s): a test that stops a run holds it first, so the run cannot end before the
#: signal arrives however fast the machine is; the driving, and so every result, is the same
HELD = """
import os
import time

from icrsumo.agents.privileged import InstructionFollower


class Held(InstructionFollower):
    name = "held-follower"

    def act(self, obs):
        hold, t0 = os.environ.get("ICRSUMO_TEST_HOLD", ""), time.monotonic()
        while hold and os.path.exists(hold) and time.monotonic() - t0 < 120:
            time.sleep(0.05)
        return super().act(obs)
"""
ARGS = ["--agent", "{agent}:Held", "--family", "paraphrase", "--k", "3", "--routes",
        "tiny_000,tiny_002", "--workers", "2", "--quiet"]
_AGENT: list[Path] = []  # the agent file, written once per module (held_agent)


@pytest.fixture(scope="module", autouse=True)
def held_agent(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("agent") / "held_agent.py"
    path.write_text(HELD, encoding="utf-8")
    _AGENT[:] = [path]
    return path


def _start(out: Path, *extra: str, args: list[str] = ARGS, hold: Path | None = None) -> subprocess.Popen:
    args = [a.format(agent=_AGENT[0]) for a in args]
    env = {**os.environ, "ICRSUMO_TEST_HOLD": str(hold or "")}
    return subprocess.Popen([sys.executable, "-m", "icrsumo", "evaluate", *args, *extra, "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            preexec_fn=_default_signals)


def _default_signals() -> None:
    """The run starts with SIGTERM and SIGHUP at their defaults, as from a shell: a test suite
    started under nohup would pass SIGHUP on ignored, and icrsumo leaves an ignored SIGHUP be."""
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)


def _children(pid: int) -> list[int]:
    path = Path(f"/proc/{pid}/task/{pid}/children")
    return [int(p) for p in path.read_text().split()] if path.exists() else []


def _stored(out: Path) -> int:
    db = out / "results.sqlite"
    if not db.exists():
        return 0
    try:
        with sqlite3.connect(db) as c:
            return c.execute("SELECT COUNT(*) FROM episodes").fetchone()[0]
    except sqlite3.Error:
        return 0


def _wait_running(p: subprocess.Popen, out: Path, processes: int = 2) -> list[int]:
    """Wait until the run has stored an episode and has its worker processes; their pids."""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        kids = _children(p.pid)
        if _stored(out) >= 1 and len(kids) >= processes:
            return kids
        assert p.poll() is None, p.stderr.read()
        time.sleep(0.2)
    raise AssertionError("the run never got going")


def _gone(pids: list[int], within: float = 10.0) -> bool:
    deadline = time.monotonic() + within
    while time.monotonic() < deadline:
        if not any(Path(f"/proc/{p}").exists() and "zombie" not in _state(p) for p in pids):
            return True
        time.sleep(0.2)
    return False


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/status").read_text().split("State:")[1].split("\n")[0].lower()
    except (OSError, IndexError):
        return "zombie"


@pytest.fixture(scope="module")
def fresh(tmp_path_factory) -> bytes:
    out = tmp_path_factory.mktemp("fresh") / "o"
    p = _start(out)
    assert p.wait(timeout=300) == 0, p.stderr.read()
    return (out / "summary.json").read_bytes()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_signal_stops_the_run_and_its_workers_and_a_rerun_resumes(tmp_path, fresh, sig):
    out, hold = tmp_path / "o", tmp_path / "hold"
    p = _start(out, hold=hold)
    workers = _wait_running(p, out)
    hold.touch()                   # the workers wait at their next decision: the run cannot end
    p.send_signal(sig)
    assert p.wait(timeout=60) == 128 + sig
    err = p.stderr.read()
    assert f"stopped by {signal.Signals(sig).name}" in err and "Traceback" not in err
    assert _gone(workers), "worker processes outlived the run"
    assert not (out / ".icrsumo.lock").exists()
    if sig == signal.SIGTERM:      # one path for both signals: the resume is checked once
        again = _start(out)
        assert again.wait(timeout=300) == 0, again.stderr.read()
        assert (out / "summary.json").read_bytes() == fresh


BATCHED = ["--agent", "bev-ngram-aug", "--family", "paraphrase", "--k", "4", "--routes", "tiny_000,tiny_002",
           "--workers", "2", "--batch-inference", "cpu", "--quiet"]


@pytest.mark.parametrize("batched", [False, True])
def test_kill_9_of_the_main_process_takes_its_workers_with_it(tmp_path, batched):
    """... and its batched-inference process too."""
    out = tmp_path / "o"
    p = _start(out, args=BATCHED if batched else ARGS)
    workers = _wait_running(p, out, 3 if batched else 2)
    os.kill(p.pid, signal.SIGKILL)
    p.wait(timeout=30)
    assert _gone(workers), "worker processes outlived a killed run"
    if not batched:
        again = _start(out)                        # the system released the folder's lock
        assert again.wait(timeout=300) == 0, again.stderr.read()


def test_two_runs_started_together_on_one_folder_one_runs_the_other_is_refused(tmp_path):
    out = tmp_path / "o"
    a, b = _start(out, "--seed", "1"), _start(out, "--seed", "2")
    codes = sorted([a.wait(timeout=300), b.wait(timeout=300)])
    errs = a.stderr.read() + b.stderr.read()
    assert codes == [0, 2], errs
    assert "another icrsumo run (pid " in errs and "is using this folder" in errs
    seed = json.loads((out / "config.json").read_text())["seed"]
    with sqlite3.connect(out / "results.sqlite") as c:
        seeds = {r[0] for r in c.execute("SELECT DISTINCT seed FROM episodes")}
    assert seeds == {seed}
