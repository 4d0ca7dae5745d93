"""Text that users and remote servers choose (agent names, phrasings) reaches the outputs
escaped per format: Markdown table cells stay cells, CSV cells never start a formula, LaTeX
specials are escaped, and a "$" in a figure is a dollar sign, not mathtext (a figure that still
fails is a note, never the end of a finished run)."""

from __future__ import annotations

import csv
import io

from icrsumo.compat.report import csv_cell, delta_bars, figure_or_note, md_cell, rd_to_plane, tables
from icrsumo.core.types import EpisodeRecord
from icrsumo.core.vocab import EpisodeStatus
from icrsumo.results.aggregate import summarize

HOSTILE = "=HYPERLINK(\"x\") | $\\frac{$ _100%\nnext"   # mathtext would fail on it


def _summary():
    recs = []
    for route in ("r1", "r2"):
        recs.append(EpisodeRecord(HOSTILE, route, "baseline", 0, 1, EpisodeStatus.DONE, ds=100.0, rc=100.0,
                                  is_=1.0, termination="route_completed", termination_class="done"))
        recs.append(EpisodeRecord(HOSTILE, route, "paraphrase", 0, 1, EpisodeStatus.DONE, ds=50.0, rc=50.0,
                                  is_=1.0, termination="route_deviation", termination_class="RD"))
    return summarize(recs, suite="t", seed=1, k=1, families=("paraphrase",))


def test_markdown_csv_and_latex_cells_hold_hostile_names():
    t = tables(_summary())
    rows = [ln for ln in t["md"].splitlines() if ln.startswith("| =HYPERLINK")]
    header = t["md"].splitlines()[0]
    assert len(rows) == 2 and all(r.count(" | ") == header.count(" | ") for r in rows)   # no extra cells
    cells = list(csv.reader(io.StringIO(t["csv"])))
    assert cells[1][0].startswith("'=HYPERLINK") and cells[1][0].endswith("next")
    assert "\\$\\textbackslash{}frac\\{" in t["tex"] and "\\_100\\%" in t["tex"]
    assert md_cell("a|b\nc") == "a\\|b c"
    assert csv_cell("-3.5") == "-3.5" and csv_cell("+SUM(A1)") == "'+SUM(A1)" and csv_cell(-3) == -3


def test_figures_draw_dollar_signs_and_a_failing_figure_is_a_note(tmp_path, capsys):
    s = _summary()
    rd_to_plane(s, tmp_path / "rd.png")
    delta_bars(s, tmp_path / "d.png")
    assert (tmp_path / "rd.png").stat().st_size > 1000 and (tmp_path / "d.png").stat().st_size > 1000

    def broken(summary, path):
        raise ValueError("matplotlib could not lay this out")

    figure_or_note(broken, s, tmp_path / "x.png")
    assert "no figure x.png: ValueError: matplotlib could not lay this out" in capsys.readouterr().err
