"""results.csv: one row per (agent, family) with the summary's numbers unrounded (RD / TO in %
with 2 decimals); the baseline row leaves the paired columns empty."""

from __future__ import annotations

from typing import Any

from icrsumo.results.summary import Block, FamilyStats, Summary

from .cells import csv_text

HEADER = ("agent", "family", "n", "n_routes", "DS", "RC", "IS", "dDS", "dDS_ci95_lo", "dDS_ci95_hi",
          "dRC", "dRC_ci95_lo", "dRC_ci95_hi", "dIS", "worst_dDS", "RD_pct", "TO_pct",
          "baseline_done_variant_failed", "n_crashed", "unpaired", "base_DS", "base_RC", "base_IS")
#: the columns an evaluation with a language-model agent adds (icrsumo.agents.llm)
ANSWERS = ("model_calls", "invalid_answers", "invalid_rate")


def _share(x: float | None) -> float | None:
    return None if x is None else round(100.0 * x, 2)


def _paired(b: FamilyStats) -> dict[str, Any]:
    """The columns only a family's row fills."""
    lo_ds, hi_ds = b.d_ds_ci95 or (None, None)
    lo_rc, hi_rc = b.d_rc_ci95 or (None, None)
    return {"n_routes": b.n_routes, "dDS": b.d_ds, "dDS_ci95_lo": lo_ds, "dDS_ci95_hi": hi_ds, "dRC": b.d_rc,
            "dRC_ci95_lo": lo_rc, "dRC_ci95_hi": hi_rc, "dIS": b.d_is, "worst_dDS": b.worst_d_ds,
            "baseline_done_variant_failed": b.baseline_done_variant_failed, "unpaired": b.unpaired,
            "base_DS": b.base_ds, "base_RC": b.base_rc, "base_IS": b.base_is}


def _row(agent: str, fam: str, b: Block, answers: bool) -> list[Any]:
    cols = {"agent": agent, "family": fam, "n": b.n, "DS": b.ds, "RC": b.rc, "IS": b.is_,
            "RD_pct": _share(b.rd), "TO_pct": _share(b.to), "n_crashed": b.n_crashed,
            **(_paired(b) if isinstance(b, FamilyStats) else {})}
    if answers and b.answers is not None:
        cols.update(b.answers.to_dict())
    return [cols.get(c) for c in (*HEADER, *(ANSWERS if answers else ()))]


def results_csv(summary: Summary) -> str:
    """The CSV text (cells safe in a spreadsheet, :func:`icrsumo.reporting.cells.csv_cell`)."""
    answers = summary.has_answers
    return csv_text((*HEADER, *ANSWERS) if answers else HEADER,
                    (_row(agent, fam, b, answers) for agent, fam, b in summary.rows()))
