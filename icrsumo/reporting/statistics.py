"""statistics.md and statistics.csv: what a reviewer asks for beside Δ and its CI, per agent and
family."""

from __future__ import annotations

from typing import Any

from icrsumo.results.summary import FamilyStats, Summary

from .cells import csv_text, md_cell, num, p_text

_HEADER = ("Agent", "Family", "routes", "ΔDS", "rel. drop DS %", "rel. drop RC %", "p (Holm)",
           "p (raw)", "flips lost", "flips gained")
_CSV = ("agent", "family", "n_routes", "dDS", "pdr_DS", "pdr_RC", "p_value", "p_value_raw",
        "flips_lost", "flips_gained")


def _percent(x: float | None) -> float | None:
    return None if x is None else 100.0 * x


def _md_row(agent: str, fam: str, b: FamilyStats) -> str:
    return "| " + " | ".join([
        md_cell(agent), fam, str(b.n_routes), num(b.d_ds, 1, True), num(_percent(b.pdr_ds), 1),
        num(_percent(b.pdr_rc), 1), p_text(b.p_value), p_text(b.p_value_raw), str(b.flips.lost),
        str(b.flips.gained)]) + " |"


def _csv_row(agent: str, fam: str, b: FamilyStats) -> list[Any]:
    return [agent, fam, b.n_routes, b.d_ds, b.pdr_ds, b.pdr_rc, b.p_value, b.p_value_raw, b.flips.lost,
            b.flips.gained]


def statistics_tables(summary: Summary) -> dict[str, str]:
    """{"md", "csv"}: per agent and family the routes paired, ΔDS, the relative drops of DS and
    RC (%), the Wilcoxon signed-rank p-value of the per-route ΔDS (Holm-corrected over the
    agent's families, and raw), and the flips of termination between baseline and variant
    (pairs that lost / gained a completed route)."""
    rows = [(agent, fam, b) for agent, a in summary.agents.items() for fam, b in a.families.items()]
    md = ["| " + " | ".join(_HEADER) + " |", "|" + "|".join(["---"] * 2 + ["---:"] * 8) + "|"]
    md += [_md_row(*row) for row in rows]
    return {"md": "\n".join(md) + "\n", "csv": csv_text(_CSV, (_csv_row(*row) for row in rows))}
