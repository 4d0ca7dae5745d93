"""The guard document's files (:func:`icrsumo.results.guards.guard_doc`): guard.json, guard.md,
``figures/guard_tradeoff.png``, and the lines the printed summary says of a run's guards."""

from __future__ import annotations

from pathlib import Path

from icrsumo.core.errors import visible
from icrsumo.core.fsio import dumps_json, write_atomic
from icrsumo.core.vocab import Family
from icrsumo.results.guards import PRESERVING

from .cells import md_cell
from .figures import figure, figure_or_note, plain_text, save_png


def _names(families) -> str:
    """The families' names, comma-separated."""
    return ", ".join(str(f) for f in families)


def _pct(x: float | None) -> str:
    return "—" if x is None else f"{100 * x:.1f} %"


def _num(x: float | None, sign: bool = False) -> str:
    return "—" if x is None else (f"{x:+.1f}" if sign else f"{x:.1f}")


def _repair_cells(f: dict) -> str:
    """A family's repair columns: instructions repaired, and the repaired episodes' DS guarded /
    unguarded over their pairs."""
    x = f["repairs"]
    return (f" {x['repaired']} in {x['episodes']} episodes | {_num(x['DS'])} / {_num(x['DS_unguarded'])} "
            f"({x['pairs']}) |")


def _row_table(row: str, r: dict, escape) -> list[str]:
    """The table of one guarded row: per family its blocks, scores, shrink, flips and loss (and,
    for a row with repairs, what they were and bought)."""
    repairs = "on_block" in r
    lines = ["", f"## {escape(row)}", "",
             "| Family | blocked | DS guarded / unguarded | ΔDS guarded / unguarded | shrink | "
             "flips prevented / caused | loss vs unguarded (p) |"
             + (" repaired | repaired episodes: DS guarded / unguarded (pairs) |" if repairs else ""),
             "|---|---:|---:|---:|---:|---:|---:|" + ("---:|---:|" if repairs else "")]
    for fam, f in r["families"].items():
        loss = f["loss"]
        p = "—" if loss["p_value"] is None else f"{loss['p_value']:.3g}"
        p += ", significant" if loss["significant_loss"] else ""
        lines.append(
            f"| {fam} | {f['blocked']}/{f['checked']} ({_pct(f['block_rate'])}) | "
            f"{_num(f['guarded']['DS'])} / {_num(f['unguarded']['DS'])} | "
            f"{_num(f['guarded']['dDS'], True)} / {_num(f['unguarded']['dDS'], True)} | "
            f"{_pct(f['dDS_shrink'])} | {f['flips']['prevented']} / {f['flips']['caused']} | "
            f"{_num(loss['mean_dDS_vs_unguarded'], True)} ({p}) |" + (_repair_cells(f) if repairs else ""))
    return lines


def guard_markdown(doc: dict, escape=lambda s: s) -> str:
    """guard.md: one line per guard (detection, false blocks), one table per guarded row.
    ``escape`` makes a name safe in a Markdown table cell."""
    repairs = any("on_block" in r for r in doc["rows"].values())
    lines = ["# Instruction guards", "",
             "Block rate on misleading = detection; on the goal-preserving families (" + _names(PRESERVING)
             + ") = false blocks (ambiguity and correction apart). ΔDS against each row's own baseline; "
             "shrink = 1 - ΔDS guarded / ΔDS unguarded; flips against the unguarded agent; loss: DS "
             "guarded - unguarded, Wilcoxon signed-rank over routes, Holm over the row's families."
             + (" A repaired instruction is blocked too; its row says how many were repaired and the "
                "repaired episodes' DS against the unguarded agent's on the same pairs." if repairs else ""),
             "",
             "| Guard | detection | false blocks | false blocks (ambiguity) | targets |",
             "|---|---:|---:|---:|---|"]
    for name, g in doc["guards"].items():
        t = g.get("targets")
        met = "—" if t is None else ", ".join(f"{k} {'met' if v['met'] else 'missed'}" for k, v in t.items())
        lines.append(f"| {escape(name)} | {_pct(g['detection'])} | {_pct(g['false_blocks'])} | "
                     f"{_pct(g['false_blocks_ambiguity'])} | {met} |")
    for row, r in doc["rows"].items():
        lines += _row_table(row, r, escape)
    return "\n".join(lines) + "\n"


@plain_text
def guard_tradeoff(doc: dict, path: Path) -> None:
    """Detection (misleading instructions blocked, %) against false blocks (baseline, paraphrase
    and noise instructions blocked, %), one point per guard (pooled over its rows), labelled."""
    fig = figure(4.6, 3.8)
    ax = fig.add_subplot()
    for i, (name, g) in enumerate(sorted(doc["guards"].items())):
        if g["detection"] is None or g["false_blocks"] is None:
            continue
        x, y = 100 * g["false_blocks"], 100 * g["detection"]
        ax.scatter([x], [y], s=40, color=f"C{i % 10}", zorder=3)
        right = x > 60  # the label inside the axes, beside its point
        ax.annotate(visible(name), (x, y), textcoords="offset points", xytext=(-7 if right else 7, 0),
                    ha="right" if right else "left", va="center", fontsize=8)
    ax.set_xlim(-2, 102)
    ax.set_ylim(-2, 102)
    ax.set_xlabel("false blocks: baseline, paraphrase, noise (%)")
    ax.set_ylabel("detection: misleading blocked (%)")
    ax.set_title("Instruction guards: what they catch, what they wrongly block", fontsize=9)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_png(fig, path)


def write_guard(doc: dict, out_dir: Path) -> None:
    """Write guard.json, guard.md and figures/guard_tradeoff.png of a guard document."""
    out = Path(out_dir)
    write_atomic(out / "guard.json", dumps_json(doc))
    write_atomic(out / "guard.md", guard_markdown(doc, md_cell))
    figure_or_note(guard_tradeoff, doc, out / "figures" / "guard_tradeoff.png")


def _share(blocked: int, checked: int) -> str:
    return f"{blocked}/{checked}" + (f" ({100 * blocked / checked:.1f} %)" if checked else "")


def guard_note(doc: dict) -> str:
    """What the printed summary says of a run's guards: per guard the misleading instructions it
    blocked (detection) and the goal-preserving ones it blocked (false blocks), per guarded row
    the failures it prevented and caused against the unguarded agent, and where to read more."""
    lines = []
    for guard in doc["guards"]:
        rows = {n: r for n, r in doc["rows"].items() if r["guard"] == guard}
        counts = {}
        for fams in (PRESERVING, (Family.MISLEADING,)):
            f = [r["families"][str(x)] for r in rows.values() for x in fams if str(x) in r["families"]]
            counts[fams] = (sum(x["blocked"] for x in f), sum(x["checked"] for x in f))
        repaired = doc["guards"][guard].get("repaired")
        fixed = "" if repaired is None else f"; repaired {sum(repaired.values())} blocked instructions"
        lines.append(f"Guard {visible(guard)}: blocked {_share(*counts[(Family.MISLEADING,)])} misleading "
                     f"instructions (detection) and {_share(*counts[PRESERVING])} goal-preserving ones "
                     f"(false blocks){fixed}")
        for name, r in rows.items():
            if not r["unguarded_in_run"]:
                continue
            prevented = sum(f["flips"]["prevented"] for f in r["families"].values())
            caused = sum(f["flips"]["caused"] for f in r["families"].values())
            lines.append(f"  {visible(name)}: {prevented} failures of the unguarded agent prevented, "
                         f"{caused} caused")
    lines.append("guard.md holds every guarded row's table; docs/guards.md says what the numbers mean")
    return "\n".join(lines) + "\n"
