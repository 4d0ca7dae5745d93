"""tools/exact_width.py (issue 48: the exact graph's act time at smaller widths, docs/performance.md):
it runs and times the shipped checkpoint and each width asked for (the times themselves are
measurements, not asserted)."""

import re
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "tools" / "exact_width.py"


def test_it_times_the_shipped_network_and_smaller_ones():
    r = subprocess.run([sys.executable, str(SCRIPT), "--widths", "8", "32", "--calls", "200"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    ms = {int(w): float(t) for w, t in re.findall(r"^width (\d+), hidden 256: ([\d.]+) ms", r.stdout, re.M)}
    assert set(ms) == {8, 32} and re.search(r"shipped, width 32, hidden 256\): [\d.]+ ms", r.stdout)
    assert all(t > 0 for t in ms.values()) and "median of 200 calls" in r.stdout


def test_it_times_the_shipped_network_on_recorded_frames(converted, tmp_path):
    from icrsumo.learn.collect import CollectOptions, collect

    collect(CollectOptions(suite=str(converted["tiny"]), passes=1, every=2, limit=1), tmp_path, quiet=True)
    r = subprocess.run([sys.executable, str(SCRIPT), "--recorded", str(tmp_path), "--calls", "60"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    m = re.search(r"on (\d+) recorded frames in order \(([\d.]+) % of the BEV patches empty\): ([\d.]+) ms "
                  r"per act afresh, ([\d.]+) ms starting from the call before", r.stdout)
    assert m and int(m[1]) == 60 and 0 < float(m[2]) < 100 and float(m[3]) > 0 and float(m[4]) > 0
    bad = subprocess.run([sys.executable, str(SCRIPT), "--recorded", str(tmp_path / "none")],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "no collected episodes found" in bad.stderr
