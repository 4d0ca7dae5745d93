"""results.md: the results table (:mod:`icrsumo.reporting.rows`) in Markdown, with its notes
(the conditioning gain, crashes) under it."""

from __future__ import annotations

from icrsumo.results.summary import Summary

from .cells import md_cell
from .rows import notes, table_cells


def results_md(summary: Summary) -> str:
    """The Markdown table (names escaped, :func:`icrsumo.reporting.cells.md_cell`)."""
    header, text_rows = table_cells(summary)
    md = ["| " + " | ".join(header) + " |", "|" + "|".join(["---"] * 2 + ["---:"] * (len(header) - 2)) + "|"]
    for agent, fam, cells in text_rows:
        md.append("| " + " | ".join([md_cell(agent), fam, *cells]) + " |")
    for note in notes(summary):
        md += ["", note]
    return "\n".join(md) + "\n"
