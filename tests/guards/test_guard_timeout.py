"""A guard's calls have the agent calls' time limit: a guard whose ``check`` hangs stops its
episode (stored as crashed, "guard NAME did not answer within N s", no retry), never the run; and
a run with a guard prints what the guard did under its table, pointing to guard.md and the docs."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from icrsumo.agents.hosting.watch import AlarmWatch, Unwatched
from icrsumo.evaluation.execute import WatchedGuard
from icrsumo.guards.base import GuardContext, GuardInfo, GuardTimeout
from icrsumo.results.store import ResultStore

HANG = '''
import time

class Hang:
    name, needs_plan = "hang", False

    def reset(self, info):
        pass

    def check(self, text, context):
        time.sleep(3600)
'''


class Slow:
    name, needs_plan = "slow", False

    def reset(self, info):
        pass

    def check(self, text, context):
        time.sleep(5)
        return "pass"


class Quick(Slow):
    def check(self, text, context):
        return "block", "no"


CTX = GuardContext(t=0.0, progress=0.0, instruction_id=0, previous="")


def test_a_watched_guard_times_out_as_an_agent_call_does():
    """Where no parent process watches (Ray workers), the alarm interrupts a hung guard call."""
    guard = WatchedGuard(Slow(), AlarmWatch(0.3), "slow")
    assert guard.name == "slow" and guard.needs_plan is False
    guard.reset(GuardInfo("r", "t"))
    t0 = time.monotonic()
    with pytest.raises(GuardTimeout, match=r"^guard slow did not answer within 0\.3 s$"):
        guard.check("Turn left.", CTX)
    assert time.monotonic() - t0 < 3
    assert WatchedGuard(Quick(), AlarmWatch(0.3), "quick").check("Turn left.", CTX) == ("block", "no")
    assert WatchedGuard(Quick(), Unwatched(), "quick").check("Turn left.", CTX) == ("block", "no")


@pytest.mark.sumo
def test_a_hung_guard_crashes_its_episodes_and_the_table_shows_the_guards(tmp_path):
    (tmp_path / "hang_guard.py").write_text(HANG)
    dist = tmp_path / "hang_guard-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: hang-guard\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[icrsumo.guards]\nhang = hang_guard:Hang\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])}
    out = tmp_path / "out"
    argv = ["evaluate", "--suite", "tiny", "--routes", "tiny_003", "--agent", "route-oracle", "--guard",
            "plan", "--guard", "hang", "--family", "misleading", "--k", "1", "--workers", "1",
            "--agent-timeout", "2", "--out", str(out)]
    run = subprocess.run([sys.executable, "-m", "icrsumo", *argv], capture_output=True, text=True, env=env,
                         timeout=400)
    assert run.returncode == 0, run.stderr
    with ResultStore(out / "results.sqlite") as store:
        records = store.records()
    crashed = [r for r in records if r.status == "crashed"]
    assert {r.agent for r in crashed} == {"route-oracle+guard:hang"} and len(crashed) == 2
    assert all(r.message == "GuardTimeout: guard hang did not answer within 2 s (its worker process was "
               "stopped)" and r.attempts == 1 for r in crashed)
    assert sum(r.status == "done" for r in records) == 4   # the agent alone and behind plan
    assert "2 crashed" in run.stderr.splitlines()[-2]
    # under the table: what each guard blocked, what it changed, and where to read more
    said = run.stdout[run.stdout.index("\nGuard "):]
    assert ("Guard plan: blocked 2/2 (100.0 %) misleading instructions (detection) and "
            "0/2 (0.0 %) goal-preserving ones (false blocks)") in said
    assert "route-oracle+guard:plan: 0 failures of the unguarded agent prevented, 0 caused" in said
    assert "Guard hang: blocked 0/0 misleading" in said
    assert "guard.md holds every guarded row's table; docs/guards.md says what the numbers mean" in said
