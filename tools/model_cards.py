"""Write the model cards ``icrsumo/learn/checkpoints/NAME.md`` from each checkpoint's metadata,
its training config and the ``summary.json`` of an ``icrsumo evaluate`` run.

    python tools/model_cards.py SUMMARY.json [--train-seconds NAME=S ...] [--eval-command CMD]
                                [--extra "LABEL=SUMMARY.json=COMMAND" ...]

``--extra`` adds a measured table per further evaluation (e.g. on LangAuto's tracks).
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
    "minilm": "the pretrained sentence encoder all-MiniLM-L6-v2 (Apache-2.0, "
              "`icrsumo/learn/encoders/NOTICE`), frozen: its 384-d embedding (8-bit weights computed "
              "exactly in numpy, shipped in the package, tokenized by `tokenizers`, computed once per "
              "distinct text) through an MLP",
}


def _row(name: str, fam: str, r: dict) -> str:
    ci = r.get("dDS_ci95")
    d = f"{r['dDS']:+.1f} [{ci[0]:+.1f}, {ci[1]:+.1f}]" if ci else ""
    return f"| {fam} | {r['DS']:.1f} | {r['RC']:.1f} | {r['IS']:.3f} | {d} | {100 * r['RD']:.0f}% |"


def _table(name: str, title: str, summary: dict, eval_cmd: str) -> list[str]:
    res = summary["agents"].get(name)
    if not res:
        return []
    lines = [
        f"## Measured evaluation ({title})", "",
        f"`{eval_cmd}` (seed {summary['seed']}, K = {summary['k']}, scored by "
        f"{SCORED_BY.get(summary.get('scoring'), 'icrsumo rules before Leaderboard 1.0')}"
        + (f"; digest `{summary['digest']}`" if summary.get("digest") else "") + "):", "",
        "| Instructions | DS | RC | IS | ΔDS [95% CI] | RD |", "|---|---|---|---|---|---|",
        _row(name, "baseline", {**res["baseline"], "dDS": 0.0, "dDS_ci95": None}),
    ]
    return lines + [_row(name, fam, r) for fam, r in res["families"].items()] + [""]


#: a summary's scoring -> the rules it names
SCORED_BY = {"lb1": "CARLA Leaderboard 1.0's rules", "lb2": "CARLA Leaderboard 2.0's rules"}

#: collect folder name -> what it holds (the command that wrote it and its routes)
DATA = {
    "train": "`icrsumo collect --out train` (the bundled `train` split: 272 routes on icrsumo's six "
             "towns that share no edge sequence with the evaluation splits; 816 episodes, 277,077 frames)",
    "carla-train": "`icrsumo collect --suite carla-train --out carla-train` (128 random routes on CARLA's "
                   "eight towns, none of which drives a whole LangAuto route; 384 episodes, 201,611 frames)",
    "carla-focus": "`icrsumo collect --suite carla-focus --out carla-focus` (92 routes on CARLA's towns, "
                   "each with a lane change across two lanes or more or a roundabout; none drives a whole "
                   "LangAuto route; 276 episodes, 116,416 frames)",
    "dagger-carla-train": "`icrsumo collect --suite carla-train --driver bev-ngram-aug --out "
                          "dagger-carla-train` (a DAgger round: the `bev-ngram-aug` shipped before this "
                          "checkpoint (exact checkpoint, SHA-256 6cb72f96..., in the git history), with its "
                          "instruction memory, drives, the expert labels; 384 episodes, 186,634 frames)",
    "dagger-carla-focus": "`icrsumo collect --suite carla-focus --driver bev-ngram-aug --out "
                          "dagger-carla-focus` (the same DAgger round on `carla-focus`; 276 episodes, "
                          "113,372 frames)",
    "dagger2-carla-train": "`icrsumo collect --suite carla-train --driver bev-ngram --passes 1 --out "
                           "dagger2-carla-train` (the `bev-ngram` shipped before (SHA-256 354c5751..., in "
                           "the git history), with its memory, drives its clean pass, the expert labels; 128 "
                           "episodes, 60,451 frames)",
    "dagger2-carla-focus": "`icrsumo collect --suite carla-focus --driver bev-ngram --passes 1 --out "
                           "dagger2-carla-focus` (the same on `carla-focus`; 92 episodes, 40,425 frames)",
}


def _data_line(folders: list[str]) -> str:
    """The collections a checkpoint was trained on, in words."""
    return "; ".join(DATA.get(f, f"`{f}`") for f in folders)


def card(name: str, summary: dict, train_s: float | None, eval_cmd: str,
         extra: list[tuple[str, dict, str]] = (), models_at_once: str = "three",
         hardware: str = "one NVIDIA H100 (the `device` tool)") -> str:
    """The model card of shipped checkpoint ``name``; ``train_s``: its training wall time (s),
    by default the one its metadata records."""
    ck = torch.load(CHECKPOINTS / f"{name}.pt", weights_only=True)
    cfg = tomllib.loads((CHECKPOINTS / f"{name}.toml").read_text())
    meta = ck["meta"]
    train_s = train_s if train_s is not None else meta.get("final", {}).get("elapsed_s")
    took = f"{train_s / 60:.1f} min" if train_s is not None else "time not recorded"
    n_par = sum(v.numel() for v in ck["model"].values())
    size = (CHECKPOINTS / f"{name}.pt").stat().st_size / 2**20
    val = meta.get("final", {}).get("val", {})
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
        f"- {n_par:,} parameters, {size:.1f} MB (float32, `{name}.pt`, loaded with "
        "`torch.load(..., weights_only=True)`); the agent runs its exact checkpoint `"
        f"{name}.npz` (8-bit weights, integer activations, the same bits on every CPU, no torch: "
        "docs/exact.md), made from it with `icrsumo export-exact`; the tables below were measured "
        "with the exact checkpoint unless they say otherwise.", "",
        "## Data and training", "",
        "- Data: " + _data_line(meta["data"]) + "; 3 passes per route unless said otherwise, pass 0 "
        "clean and passes 1-2 with perturbations for recovery (none where a learned agent drives); "
        "route-oracle expert labels (its final standstill dropped where it got stuck); 5 Hz; each frame "
        "records the text the instruction memory hands the network (issue 47). "
        f"{meta['frames']:,} training frames; the routes with `val_fraction` held out for validation. "
        "Neither LangAuto's evaluation routes nor the evaluation template banks are ever read.",
        "- Instructions: baseline phrasings only (baseline bank)"
        + (", plus paraphrase and noise variants from the training bank "
           "`icrsumo/learn/data/train_bank.json` (`--augment-instructions`)" if cfg["augment_instructions"]
           else "") + "; the evaluation banks are never read.",
        f"- Config: [`{name}.toml`]({name}.toml): {meta['steps']:,} steps, batch {cfg['batch']}, "
        f"AdamW, one-cycle lr {cfg['lr']}, seed {cfg['seed']}.",
        f"- Command: `bash tools/train_shipped.sh OUT {' '.join(meta['data'])}` (runs `python -m icrsumo "
        f"train icrsumo/learn/checkpoints/{name}.toml {' '.join('--data ' + d for d in meta['data'])} "
        f"--out OUT/{name}`), on {hardware}, {models_at_once} models at once; {took}.",
        f"- Validation at the end: waypoint L1 {val.get('waypoints', float('nan')):.3f} m, last point "
        f"error {val.get('final_wp_err', float('nan')):.2f} m, target-speed L1 "
        f"{val.get('speed', float('nan')):.2f} m/s, stop accuracy {val.get('stop_acc', float('nan')):.3f}, "
        f"intent accuracy {val.get('intent_acc', float('nan')):.3f}.", "",
    ]
    lines += _table(name, "bundled tiny suite, never trained on", summary, eval_cmd)
    for label, extra_summary, cmd in extra:
        lines += _table(name, label, extra_summary, cmd)
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("summary", type=Path)
    ap.add_argument("--train-seconds", action="append", default=[],
                    help="NAME=SECONDS (default: the training time in the checkpoint's metadata)")
    ap.add_argument("--eval-command", default="icrsumo evaluate --agent NAME")
    ap.add_argument("--extra", action="append", default=[], help="LABEL=SUMMARY.json=COMMAND")
    ap.add_argument("--note", action="append", default=[],
                    help="NAME=TEXT: a paragraph under 'Other measurements' in NAME's card")
    ap.add_argument("--only", action="append", default=[], help="write only these cards (repeatable)")
    ap.add_argument("--data", action="append", default=[],
                    help="FOLDER=TEXT: describe a data folder so (instead of the built-in description)")
    ap.add_argument("--at-once", default="three", help="how many models were trained at once (words)")
    ap.add_argument("--hardware", default="one NVIDIA H100 (the `device` tool)",
                    help="what the models were trained on (words)")
    args = ap.parse_args()
    DATA.update(dict(x.split("=", 1) for x in args.data))
    extra = []
    for item in args.extra:
        label, path, cmd = item.split("=", 2)
        extra.append((label, json.loads(Path(path).read_text()), cmd))
    summary = json.loads(args.summary.read_text())
    secs = {k: float(v) for k, v in (s.split("=", 1) for s in args.train_seconds)}
    for p in sorted(CHECKPOINTS.glob("*.pt")):
        if args.only and p.stem not in args.only:
            continue
        card_text = card(p.stem, summary, secs.get(p.stem), args.eval_command, extra, args.at_once,
                         args.hardware)
        notes = [t for n, t in (x.split("=", 1) for x in args.note) if n == p.stem]
        if notes:
            card_text += "\n" + "\n".join(["## Other measurements", "", *(f"{t}\n" for t in notes)])
        (CHECKPOINTS / f"{p.stem}.md").write_text(card_text)
        print(f"wrote {CHECKPOINTS / (p.stem + '.md')}")


if __name__ == "__main__":
    main()
