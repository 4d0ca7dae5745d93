"""tools/is_at_reach.py (docs/scoring.md, "Why IS rises under misleading text") on a real stored
run: the IS rebuilt from the logs' penalised events equals the stored IS (no outside-lanes penalty on
these routes), and cutting the baseline at the paired episode's reach can only raise its IS."""

import subprocess
import sys
from pathlib import Path

import icrsumo

SCRIPT = Path(__file__).resolve().parents[1] / "tools" / "is_at_reach.py"
sys.path.insert(0, str(SCRIPT.parent))

import is_at_reach  # noqa: E402


def test_rebuilt_is_matches_the_store_and_the_cut_only_raises_it(tmp_path):
    out = tmp_path / "run"
    icrsumo.evaluate(agents="bev-ngram-aug", families="misleading", k=2, routes=["tiny_003", "tiny_007"],
                     out=out, workers=1)
    rows = is_at_reach.analyse(out, "misleading")
    assert [r["agent"] for r in rows] == ["bev-ngram-aug"] and rows[0]["pairs"] == 4
    r = rows[0]
    assert abs(r["events_is"] - r["is"]) < 1e-9
    assert r["cut_is"] >= r["base_is"] - 1e-12 and 0.0 < r["share"] <= 1.0
    p = subprocess.run([sys.executable, str(SCRIPT), str(out)], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0 and p.stdout.splitlines()[2].startswith("| `bev-ngram-aug` | 4 |")
    bad = subprocess.run([sys.executable, str(SCRIPT), str(tmp_path)], capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and "no results.sqlite" in bad.stderr.strip().splitlines()[-1]
