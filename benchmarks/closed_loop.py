"""Closed-loop cost vs SUMO alone: now part of ``tools/benchmark.py``.

This wrapper runs ``tools/benchmark.py --skip-eval`` with the given options (``--route``,
``--split``, ``--repeats``, ``--agents``, ``--quick``, ...); see that script's docstring for
what is measured and how.

    python benchmarks/closed_loop.py [--route tiny_004] [--repeats 5]
"""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

if __name__ == "__main__":
    script = Path(__file__).resolve().parents[1] / "tools" / "benchmark.py"
    sys.argv = [str(script), "--skip-eval", *sys.argv[1:]]
    runpy.run_path(str(script), run_name="__main__")
