"""tools/guard_tradeoff.py (docs/guards.md's tables of guards and block policies): one line per
guarded row of each folder, the executed misleading decisions read from summary.json, the
figure written, a folder without guard.json refused in one line."""

import json
import subprocess
import sys
from pathlib import Path

from icrsumo.core.types import EpisodeRecord
from icrsumo.core.vocab import EpisodeStatus
from icrsumo.reporting.guard import write_guard
from icrsumo.results.aggregate import summarize
from icrsumo.results.guards import guard_doc

SCRIPT = Path(__file__).resolve().parents[1] / "tools" / "guard_tradeoff.py"


def _rec(agent, route, family, k, ds, checked=0, blocked=0):
    done = ds == 100.0
    return EpisodeRecord(agent, route, family, k, 1, EpisodeStatus.DONE, ds=ds, rc=ds, is_=1.0,
                         termination="route_completed" if done else "route_deviation",
                         termination_class="done" if done else "RD", guard_checked=checked,
                         guard_blocked=blocked)


def _folder(path: Path) -> None:
    recs = []
    for r in ("r1", "r2", "r3"):
        recs += [_rec("a", r, "baseline", 0, 100.0), _rec("a+guard:plan", r, "baseline", 0, 100.0, 2, 0)]
        for k in (0, 1):
            recs += [_rec("a", r, "misleading", k, 40.0),
                     _rec("a+guard:plan", r, "misleading", k, 70.0, 2, 1),
                     _rec("a", r, "noise", k, 100.0),
                     _rec("a+guard:plan", r, "noise", k, 100.0, 2, int(k))]
    summary = summarize(recs, suite="t", seed=1, k=2, families=("noise", "misleading"))
    write_guard(guard_doc(summary, recs), path)
    # decision-level attribution of the misleading episodes, as summary.json holds it
    decisions = {"a": {"followed_route": 1, "followed_text": 5, "other": 0, "not_reached": 0},
                 "a+guard:plan": {"followed_route": 4, "followed_text": 2, "other": 0, "not_reached": 0}}
    (path / "summary.json").write_text(json.dumps(
        {"agents": {name: {"families": {"misleading": {"decisions": d}}} for name, d in decisions.items()}}))


def test_one_line_per_guarded_row_and_the_figure(tmp_path):
    _folder(tmp_path / "keep")
    png = tmp_path / "f.png"
    r = subprocess.run([sys.executable, str(SCRIPT), str(tmp_path / "keep"), "--figure", str(png)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    line = r.stdout.splitlines()[2]
    assert line.startswith("| `a` | plan | keep | 6/12 (50.0 %) | −60.0 → −30.0 (50 %) | 5 of 6 → 2 of 6 |")
    assert "| 3/18 (16.7 %) |" in line  # baseline 0/6 and noise 3/12 blocked
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_folder_without_guards_is_refused_in_one_line(tmp_path):
    r = subprocess.run([sys.executable, str(SCRIPT), str(tmp_path)], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2 and "no guard.json" in r.stderr.strip().splitlines()[-1]
