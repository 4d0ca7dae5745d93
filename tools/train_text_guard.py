"""Train the ``text-learned`` guard's shipped weights and print its held-out numbers beside the
``text`` rule guard's (docs/guards.md). CPU, seconds; deterministic from ``--seed``.

    python tools/train_text_guard.py                 # writes icrsumo/learn/data/text_guard.npz
    python tools/train_text_guard.py --out OTHER.npz --seed 1
"""

from __future__ import annotations

import argparse
import json

from icrsumo.guards.text import TextGuard
from icrsumo.instructions.banks import load_banks
from icrsumo.learn.text_guard import WEIGHTS, LearnedTextGuard
from icrsumo.learn.text_guard_train import heldout_sets, measure, train, training_set


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=str(WEIGHTS))
    args = ap.parse_args()
    banks = load_banks()
    texts, y = training_set(banks, args.seed)
    model = train(banks, args.seed)
    model.save(args.out)
    sets = heldout_sets(banks)
    sizes = {"texts": len(texts), "positives": int(y.sum()), "negatives": int(len(y) - y.sum())}
    print(json.dumps({"training": sizes, "threshold": model.threshold, "text": measure(TextGuard(), sets),
                      "text-learned": measure(LearnedTextGuard(model), sets)}, indent=1))


if __name__ == "__main__":
    main()
