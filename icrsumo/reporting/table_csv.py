"""results.csv: one row per (agent, family) with the summary's numbers unrounded (RD / TO in %
with 2 decimals); the baseline row leaves the paired columns empty. A run with the ``blank``
family adds the :data:`GAIN` columns, filled on each agent's blank row; a run in which an agent
asked for clarification the :data:`ASKS` columns (rates as fractions)."""

from __future__ import annotations

from typing import Any

from icrsumo.core.vocab import Family
from icrsumo.results.summary import Block, ConditioningGain, FamilyStats, Summary

from .cells import csv_text

HEADER = ("agent", "family", "n", "n_routes", "DS", "RC", "IS", "dDS", "dDS_ci95_lo", "dDS_ci95_hi",
          "dRC", "dRC_ci95_lo", "dRC_ci95_hi", "dIS", "worst_dDS", "RD_pct", "TO_pct",
          "baseline_done_variant_failed", "n_crashed", "unpaired", "base_DS", "base_RC", "base_IS")
#: the columns an evaluation with a language-model agent adds (icrsumo.agents.llm)
ANSWERS = ("model_calls", "invalid_answers", "invalid_rate")
#: the columns a run in which an agent asked for clarification adds (icrsumo.sim.asking)
ASKS = ("asks", "asks_answered", "ask_rate", "asks_per_episode", "answered_rate")
#: the columns a run with the blank family adds: the agent's conditioning gain (baseline − blank)
GAIN = ("gain_DS", "gain_DS_ci95_lo", "gain_DS_ci95_hi", "gain_RC", "gain_RC_ci95_lo", "gain_RC_ci95_hi",
        "gain_IS")


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


def _gain(g: ConditioningGain) -> dict[str, Any]:
    """The :data:`GAIN` columns of an agent's blank row."""
    lo_ds, hi_ds = g.ds_ci95 or (None, None)
    lo_rc, hi_rc = g.rc_ci95 or (None, None)
    return {"gain_DS": g.ds, "gain_DS_ci95_lo": lo_ds, "gain_DS_ci95_hi": hi_ds, "gain_RC": g.rc,
            "gain_RC_ci95_lo": lo_rc, "gain_RC_ci95_hi": hi_rc, "gain_IS": g.is_}


def _row(agent: str, fam: str, b: Block, header: tuple[str, ...], gain: ConditioningGain | None) -> list[Any]:
    cols = {"agent": agent, "family": fam, "n": b.n, "DS": b.ds, "RC": b.rc, "IS": b.is_,
            "RD_pct": _share(b.rd), "TO_pct": _share(b.to), "n_crashed": b.n_crashed,
            **(_paired(b) if isinstance(b, FamilyStats) else {})}
    if b.answers is not None:
        cols.update(b.answers.to_dict())
    if b.asking is not None:
        cols.update(b.asking.to_dict())
    if fam == Family.BLANK and gain is not None:
        cols.update(_gain(gain))
    return [cols.get(c) for c in header]


def results_csv(summary: Summary) -> str:
    """The CSV text (cells safe in a spreadsheet, :func:`icrsumo.reporting.cells.csv_cell`)."""
    header = (*HEADER, *(GAIN if summary.has_conditioning_gain else ()),
              *(ANSWERS if summary.has_answers else ()), *(ASKS if summary.has_asks else ()))
    return csv_text(header, (_row(agent, fam, b, header, summary.agents[agent].conditioning_gain)
                             for agent, fam, b in summary.rows()))
