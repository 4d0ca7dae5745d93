"""Deprecated: the reports moved to :mod:`icrsumo.reporting` (one writer per module); these
names stay importable from here for old imports and take a :class:`icrsumo.results.summary.Summary`."""

from __future__ import annotations

from icrsumo.reporting.attribution import write_attribution
from icrsumo.reporting.cells import csv_cell, md_cell
from icrsumo.reporting.figures import delta_bars, figure_or_note, rd_to_plane
from icrsumo.reporting.rollout import paired_rollout
from icrsumo.reporting.tables import tables
from icrsumo.reporting.write import write_report

__all__ = ["csv_cell", "delta_bars", "figure_or_note", "md_cell", "paired_rollout", "rd_to_plane", "tables",
           "write_attribution", "write_report"]
