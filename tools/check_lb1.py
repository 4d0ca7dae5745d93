"""Rescore every stored episode of an evaluation folder with the leaderboard's code transcribed
independently in tests/lb1_reference.py, and compare with the stored Leaderboard 1.0 scores.

    python tools/check_lb1.py OUT [OUT ...]

Prints, per folder, the episodes compared, the largest |difference| of DS, RC and IS, how many
differ by more than 1e-4 and how many terminations disagree; exit status 1 when any does.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import lb1_reference  # noqa: E402

from icrsumo.results.store import ResultStore  # noqa: E402


def check(out: Path) -> bool:
    worst = {"ds": 0.0, "rc": 0.0, "is": 0.0}
    n = off = term = 0
    with ResultStore(out / "results.sqlite") as store:
        for r in store.records():
            if r.status != "done":
                continue
            ref = lb1_reference.score(store.episode_log(r.agent, r.route_id, r.family, r.k, r.seed))
            diffs = {"ds": abs(ref["score_composed"] - r.ds), "rc": abs(ref["score_route"] - r.rc),
                     "is": abs(ref["score_penalty"] - r.is_)}
            worst = {k: max(worst[k], v) for k, v in diffs.items()}
            n += 1
            off += any(v > 1e-4 for v in diffs.values())
            term += ref["ended"] not in (str(r.termination), None)
    print(f"{out}: {n} episodes; largest |diff| DS {worst['ds']:.2e}, RC {worst['rc']:.2e}, "
          f"IS {worst['is']:.2e}; {off} beyond 1e-4, {term} terminations differ")
    return off == 0 and term == 0


def main() -> int:
    ok = all([check(Path(p)) for p in sys.argv[1:]])
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
