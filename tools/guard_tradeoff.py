"""Compare guards and block policies across evaluation folders: one Markdown table per guarded
row and one figure, from the folders' ``guard.json`` and ``summary.json`` (no SUMO).

    python tools/guard_tradeoff.py OUT [OUT ...] [--figure PNG]

Each OUT is an ``icrsumo evaluate`` folder with guarded rows (``--guard``; the two block
policies live in two folders, ``on_block`` being part of a folder's configuration). Printed, per
guarded row: misleading instructions blocked, the misleading ΔDS unguarded → guarded and its
shrink, the misleading decisions executed (the agent took the text's branch: decision-level
attribution's ``followed_text``) unguarded → guarded, false blocks on the goal-preserving families,
and the goal-preserving families with a significant loss. The figure has two panels: detection
against false blocks per guard, and the misleading ΔDS shrink (mean over the guard's agents,
bars from the lowest to the highest) against the mean DS change on the goal-preserving families,
per guard and policy.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

PRESERVING = ("baseline", "paraphrase", "noise", "timing", "distance", "notice")


def executed(out: Path) -> dict[tuple[str, str], tuple[int, int]]:
    """(row, family) -> (decisions that followed the text, decisions in all) from the folder's
    summary.json (each row's decision-level attribution, ``decisions``)."""
    found: dict[tuple[str, str], tuple[int, int]] = {}
    path = out / "summary.json"
    if not path.is_file():
        return found
    for name, a in json.loads(path.read_text(encoding="utf-8"))["agents"].items():
        for fam, block in a.get("families", {}).items():
            d = block.get("decisions")
            if d:
                found[(name, fam)] = (d["followed_text"], sum(d.values()))
    return found


def rows(outs: list[Path]) -> list[dict]:
    """One entry per guarded row of every folder, in folder then row order."""
    table = []
    for out in outs:
        doc = json.loads((out / "guard.json").read_text(encoding="utf-8"))
        done = executed(out)
        for name, r in doc["rows"].items():
            fams = r["families"]
            mis = fams.get("misleading", {})
            pres = [fams[f] for f in PRESERVING if f in fams]
            checked = sum(f["checked"] for f in pres)
            ds_change = [f["loss"]["mean_dDS_vs_unguarded"] for f in pres
                         if f.get("loss", {}).get("mean_dDS_vs_unguarded") is not None]
            table.append({
                "folder": out.name, "row": name, "agent": r["agent"], "guard": r["guard"],
                "policy": r.get("on_block", "keep"),
                "mis_blocked": (mis.get("blocked", 0), mis.get("checked", 0)),
                "dDS": (mis.get("unguarded", {}).get("dDS"), mis.get("guarded", {}).get("dDS")),
                "shrink": mis.get("dDS_shrink"),
                "executed": (done.get((r["agent"], "misleading")), done.get((name, "misleading"))),
                "false_blocks": (sum(f["blocked"] for f in pres), checked),
                "ambiguity": (fams.get("ambiguity", {}).get("blocked", 0),
                              fams.get("ambiguity", {}).get("checked", 0)),
                "pres_dDS": sum(ds_change) / len(ds_change) if ds_change else None,
                "loss": [f for f in PRESERVING if fams.get(f, {}).get("loss", {}).get("significant_loss")],
            })
    return table


def _share(pair: tuple[int, int]) -> str:
    n, d = pair
    return f"{n}/{d} ({100 * n / d:.1f} %)" if d else "—"


def _num(x: float | None, sign: bool = True) -> str:
    return "—" if x is None else (f"{x:+.1f}" if sign else f"{x:.1f}").replace("-", "−")


def _exec(pair) -> str:
    return "—" if pair is None else f"{pair[0]} of {pair[1]}"


def markdown(table: list[dict]) -> str:
    """The docs' table: one line per guarded row."""
    lines = ["| agent | guard | policy | misleading blocked | misleading ΔDS unguarded → guarded (shrink) "
             "| misleading decisions executed, unguarded → guarded | false blocks (goal-preserving) "
             "| ambiguity blocked | DS change on goal-preserving families | significant loss |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|---|"]
    for t in table:
        un, gu = t["dDS"]
        shrink = "" if t["shrink"] is None else f" ({100 * t['shrink']:.0f} %)"
        ex_un, ex_gu = t["executed"]
        guard = t["guard"].split("+")[0]
        lines.append(f"| `{t['agent']}` | {guard} | {t['policy']} | {_share(t['mis_blocked'])} | "
                     f"{_num(un)} → {_num(gu)}{shrink} | {_exec(ex_un)} → {_exec(ex_gu)} | "
                     f"{_share(t['false_blocks'])} | {_share(t['ambiguity'])} | {_num(t['pres_dDS'])} | "
                     f"{', '.join(t['loss']) or 'none'} |")
    return "\n".join(lines) + "\n"


def figure(table: list[dict], path: Path) -> None:
    """Two panels: detection vs false blocks per guard; misleading ΔDS shrink vs DS change on the
    goal-preserving families per guard and policy (mean over agents, range as bars)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups: dict[tuple[str, str], list[dict]] = {}
    for t in table:
        groups.setdefault((t["guard"].split("+")[0], t["policy"]), []).append(t)
    guards = sorted({g for g, _ in groups})
    colour = {g: f"C{i}" for i, g in enumerate(guards)}
    marker = {"keep": "o", "navigator": "s"}
    fig, (a, b) = plt.subplots(1, 2, figsize=(9.6, 4.0))
    for (guard, policy), ts in sorted(groups.items()):
        mis = [sum(t["mis_blocked"][0] for t in ts), sum(t["mis_blocked"][1] for t in ts)]
        fb = [sum(t["false_blocks"][0] for t in ts), sum(t["false_blocks"][1] for t in ts)]
        if policy == "keep" or not any(g == guard and p == "keep" for g, p in groups):
            a.scatter([100 * fb[0] / max(fb[1], 1)], [100 * mis[0] / max(mis[1], 1)], color=colour[guard],
                      s=40, zorder=3)
            a.annotate(guard, (100 * fb[0] / max(fb[1], 1), 100 * mis[0] / max(mis[1], 1)),
                       textcoords="offset points", xytext=(6, -3), fontsize=8)
        shrink = [100 * t["shrink"] for t in ts if t["shrink"] is not None]
        change = [t["pres_dDS"] for t in ts if t["pres_dDS"] is not None]
        if not shrink or not change:
            continue
        x, y = sum(change) / len(change), sum(shrink) / len(shrink)
        b.errorbar([x], [y], yerr=[[y - min(shrink)], [max(shrink) - y]], fmt=marker[policy],
                   color=colour[guard], capsize=3, zorder=3, label=f"{guard}, {policy}")
    top = max(5.0, 1.15 * max(100 * t["false_blocks"][0] / max(t["false_blocks"][1], 1) for t in table))
    a.set(xlim=(-0.05 * top, top), ylim=(-2, 102),
          xlabel="false blocks: goal-preserving families (%)",
          ylabel="detection: misleading blocked (%)", title="What a guard catches")
    b.set(xlabel="DS change on goal-preserving families (mean over agents)",
          ylabel="misleading ΔDS shrink (%)", ylim=(-5, 110),
          title="What blocking buys (mean; bars: range over agents)")
    lo, hi = b.get_xlim()
    b.set_xlim(min(lo, -5.0), max(hi, 5.0))
    b.axvline(0, color="grey", lw=0.6)
    b.legend(fontsize=7, loc="lower left")
    for ax in (a, b):
        ax.grid(alpha=0.3)
        ax.title.set_fontsize(9)
    fig.tight_layout()
    fig.savefig(path, dpi=120, metadata={"Software": None})
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("outs", nargs="+", type=Path, help="icrsumo evaluate folders with guarded rows")
    p.add_argument("--figure", type=Path, help="write the two-panel figure here (PNG)")
    args = p.parse_args(argv)
    for out in args.outs:
        if not (out / "guard.json").is_file():
            p.error(f"{out}: no guard.json (fix: an evaluate folder run with --guard)")
    table = rows(args.outs)
    print(markdown(table), end="")
    if args.figure is not None:
        figure(table, args.figure)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
