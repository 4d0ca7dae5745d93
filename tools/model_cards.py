"""Write the model cards ``icrsumo/learn/checkpoints/NAME.md`` from each checkpoint's metadata,
its training config and the ``summary.json`` of an ``icrsumo evaluate`` run.

    python tools/model_cards.py SUMMARY.json [--train-seconds NAME=S ...] [--eval-command CMD]
"""

from __future__ import annotations

import argparse
import json
import tomllib
from pathlib import Path

import torch

from icrsumo.learn.agent import CHECKPOINTS

ENCODERS = {
    "token": "word tokens (vocabulary of the baseline training phrasings, numbers as `<num>`), "
             "64-d embeddings, bidirectional GRU (2 x 64)",
    "ngram": "hashed character 3- to 5-grams plus whole words (CRC-32 into 8,192 buckets), 64-d "
             "embeddings, masked mean, 2-layer MLP",
}


def _row(name: str, fam: str, r: dict) -> str:
    ci = r.get("dDS_ci95")
    d = f"{r['dDS']:+.1f} [{ci[0]:+.1f}, {ci[1]:+.1f}]" if ci else ""
    return f"| {fam} | {r['DS']:.1f} | {r['RC']:.1f} | {r['IS']:.3f} | {d} | {100 * r['RD']:.0f}% |"


def card(name: str, summary: dict, train_s: str, eval_cmd: str) -> str:
    ck = torch.load(CHECKPOINTS / f"{name}.pt", weights_only=True)
    cfg = tomllib.loads((CHECKPOINTS / f"{name}.toml").read_text())
    meta = ck["meta"]
    n_par = sum(v.numel() for v in ck["model"].values())
    size = (CHECKPOINTS / f"{name}.pt").stat().st_size / 2**20
    val = meta.get("final", {}).get("val", {})
    res = summary["agents"].get(name)
    lines = [
        f"# `{name}` model card", "",
        f"`icrsumo evaluate --agent {name}`. A learned, non-privileged agent: it sees the BEV raster "
        "(7 x 128 x 128, 0.5 m/px), its speed, the time it has been stopped and the active "
        "instruction text; never the route. It predicts 8 path points (2.5-20 m of arc, ego frame), a "
        "target speed and a stop probability, tracked by the built-in controller at 10 Hz.", "",
        "## Model", "",
        f"- Language encoder: {ENCODERS[cfg['encoder']]}.",
        "- BEV encoder: 4 convolutions (stride 4, 2, 2, 2; 32-64-128-128 channels), the language "
        "vector modulating the 8 x 8 map (FiLM), then a 256-d feature; fusion MLP with the "
        "language vector, speed and stopped time; auxiliary intent head on the language vector.",
        f"- {n_par:,} parameters, {size:.1f} MB (float32), loaded with "
        "`torch.load(..., weights_only=True)`.", "",
        "## Data and training", "",
        "- Data: `icrsumo collect --out DATA` (defaults: the bundled `train` split, 272 routes that "
        "share no edge sequence with the evaluation splits; 3 passes per route, pass 0 clean and "
        "passes 1-2 with perturbations for recovery; route-oracle expert labels; 5 Hz). "
        f"{meta['frames']:,} training frames; the routes with `val_fraction` held out for validation.",
        "- Instructions: baseline phrasings only (baseline bank)"
        + (", plus paraphrase and noise variants from the training bank "
           "`icrsumo/learn/data/train_bank.json` (`--augment-instructions`)" if cfg["augment_instructions"]
           else "") + "; the evaluation banks are never read.",
        f"- Config: [`{name}.toml`]({name}.toml): {meta['steps']:,} steps, batch {cfg['batch']}, "
        f"AdamW, one-cycle lr {cfg['lr']}, seed {cfg['seed']}.",
        f"- Command: `bash tools/train_shipped.sh OUT DATA` (runs `python -m icrsumo train "
        f"icrsumo/learn/checkpoints/{name}.toml --data DATA --out OUT/{name}`), on one NVIDIA H100 "
        f"(the `device` tool), three models at once; {train_s}.",
        f"- Validation at the end: waypoint L1 {val.get('waypoints', float('nan')):.3f} m, last point "
        f"error {val.get('final_wp_err', float('nan')):.2f} m, target-speed L1 "
        f"{val.get('speed', float('nan')):.2f} m/s, stop accuracy {val.get('stop_acc', float('nan')):.3f}, "
        f"intent accuracy {val.get('intent_acc', float('nan')):.3f}.", "",
    ]
    if res:
        lines += [
            "## Measured evaluation (bundled tiny suite, never trained on)", "",
            f"`{eval_cmd}` (seed {summary['seed']}, K = {summary['k']}):", "",
            "| Instructions | DS | RC | IS | ΔDS [95% CI] | RD |", "|---|---|---|---|---|---|",
            _row(name, "baseline", {**res["baseline"], "dDS": 0.0, "dDS_ci95": None}),
        ]
        lines += [_row(name, fam, r) for fam, r in res["families"].items()]
        lines.append("")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("summary", type=Path)
    ap.add_argument("--train-seconds", action="append", default=[], help="NAME=SECONDS")
    ap.add_argument("--eval-command", default="icrsumo evaluate --agent NAME")
    args = ap.parse_args()
    summary = json.loads(args.summary.read_text())
    secs = dict(s.split("=", 1) for s in args.train_seconds)
    for p in sorted(CHECKPOINTS.glob("*.pt")):
        t = f"{float(secs[p.stem]) / 60:.1f} min" if p.stem in secs else "time not recorded"
        (CHECKPOINTS / f"{p.stem}.md").write_text(card(p.stem, summary, t, args.eval_command))
        print(f"wrote {CHECKPOINTS / (p.stem + '.md')}")


if __name__ == "__main__":
    main()
