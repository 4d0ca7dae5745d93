"""The results table in its three files at once (:mod:`icrsumo.reporting.table_md`,
:mod:`~icrsumo.reporting.table_csv`, :mod:`~icrsumo.reporting.table_tex`)."""

from __future__ import annotations

from icrsumo.results.summary import Summary

from .table_csv import results_csv
from .table_md import results_md
from .table_tex import results_tex


def tables(summary: Summary) -> dict[str, str]:
    """The ICR-Drive Table 1 layout as {"md", "csv", "tex"}: one row per (agent, family), the
    baseline row first per agent. Markdown/LaTeX show DS, RC, deltas with 1 decimal, IS with 3,
    RD/TO in % of the family's episodes; CSV has the unrounded summary numbers."""
    return {"md": results_md(summary), "csv": results_csv(summary), "tex": results_tex(summary)}
