"""The files of an evaluation's summary and records: summary.json, results.{md,csv,tex},
statistics.{md,csv}, episodes.csv, figures/rd_to.png, figures/delta_bars.png and the
leaderboard results files (as the run's scoring writes them, :mod:`icrsumo.scoring`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from icrsumo.core.fsio import dumps_json, write_atomic
from icrsumo.core.types import EpisodeRecord
from icrsumo.results.aggregate import EPISODE_COLUMNS, episode_table
from icrsumo.results.summary import BASELINE, Summary
from icrsumo.scoring import get_scoring
from icrsumo.scoring.base import KeyPoints
from icrsumo.scoring.leaderboard import Logs

from .cells import csv_text, file_name
from .figures import delta_bars, figure_or_note, rd_to_plane
from .statistics import statistics_tables
from .tables import tables


def write_leaderboard(summary: Summary, records: Sequence[EpisodeRecord], out_dir: Path,
                      key_points: KeyPoints | None = None, logs: Logs | None = None) -> None:
    """leaderboard/<agent>_<family>.json (baseline included) for every agent and family with
    records, in the layout of the summary's scoring; ``key_points``: route id -> the route
    file's waypoints, where known; ``logs``: a crashed episode's stored log, where there is
    one (:meth:`icrsumo.scoring.Scoring.leaderboard_file`)."""
    checkpoint = get_scoring(summary.scoring).leaderboard_file
    for agent in summary.agents:
        for fam in [BASELINE, *summary.families]:
            cp = checkpoint(records, agent, fam, key_points=key_points, logs=logs)
            if cp["_checkpoint"]["records"]:
                write_atomic(Path(out_dir) / "leaderboard" / f"{file_name(agent)}_{file_name(fam)}.json",
                             dumps_json(cp))


def write_report(summary: Summary, records: Sequence[EpisodeRecord], out_dir: Path,
                 ends: dict | None = None, key_points: KeyPoints | None = None,
                 logs: Logs | None = None) -> str:
    """Write summary.json, results.{md,csv,tex}, statistics.{md,csv}, episodes.csv, figures/rd_to.png,
    figures/delta_bars.png and leaderboard/<agent>_<family>.json (baseline included) under
    ``out_dir``; returns the Markdown table. ``ends``: the episodes' log facts for episodes.csv
    (:func:`icrsumo.results.aggregate.episode_table`); ``key_points``, ``logs``: the routes'
    waypoints and the crashed episodes' stored logs for the leaderboard files
    (:func:`write_leaderboard`); paired rollout figures are written by the caller."""
    out = Path(out_dir)
    write_atomic(out / "summary.json", summary.to_json())
    t = tables(summary)
    write_atomic(out / "results.md", t["md"])
    write_atomic(out / "results.csv", t["csv"])
    write_atomic(out / "results.tex", t["tex"])
    st = statistics_tables(summary)
    write_atomic(out / "statistics.md", st["md"])
    write_atomic(out / "statistics.csv", st["csv"])
    rows = episode_table(records, ends)
    write_atomic(out / "episodes.csv", csv_text(EPISODE_COLUMNS, ([row[c] for c in EPISODE_COLUMNS]
                                                                   for row in rows)))
    figure_or_note(rd_to_plane, summary, out / "figures" / "rd_to.png")
    figure_or_note(delta_bars, summary, out / "figures" / "delta_bars.png")
    write_leaderboard(summary, records, out, key_points, logs)
    return t["md"]
