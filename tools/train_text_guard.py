"""Train the ``text-learned`` guard's shipped weights and print its held-out numbers beside the
``text`` rule guard's (docs/guards.md). CPU, a few minutes (grouped cross-validation of the L2
penalty); deterministic from ``--seed``.

    python tools/train_text_guard.py                 # writes icrsumo/learn/data/text_guard.npz
    python tools/train_text_guard.py --out OTHER.npz --seed 1
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from icrsumo.guards.text import TextGuard
from icrsumo.instructions.banks import load_banks
from icrsumo.learn.text_guard import WEIGHTS, LearnedTextGuard
from icrsumo.learn.text_guard_train import heldout_sets, measure, train, training_data, written_heldout_sets

#: the written held-out set (tests/data/guard_heldout; never trained on)
HELDOUT = Path(__file__).resolve().parents[1] / "tests" / "data" / "guard_heldout" / "heldout.json"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=str(WEIGHTS))
    ap.add_argument("--heldout", default=str(HELDOUT), help="the written held-out set ('' to skip)")
    args = ap.parse_args()
    banks = load_banks()
    data = training_data(banks, args.seed)
    model, runs = train(banks, args.seed)
    model.save(args.out)
    sets = heldout_sets(banks)
    if args.heldout:
        path = Path(args.heldout)
        sets |= written_heldout_sets(path) | written_heldout_sets(path, by_kind=True)
    sizes = {"texts": len(data.texts), "positives": int(data.labels.sum()),
             "negatives": int(len(data.labels) - data.labels.sum()), "groups": len(set(data.groups))}
    cv = [{"l2": r.l2, "threshold": r.threshold, "detection": round(r.detection, 4)} for r in runs]
    guards = {g.name: measure(g, sets) for g in (TextGuard(), LearnedTextGuard(model))}
    print(json.dumps({"training": sizes, "cross_validation": cv, "l2": model.l2, "threshold": model.threshold,
                      **guards}, indent=1))


if __name__ == "__main__":
    main()
