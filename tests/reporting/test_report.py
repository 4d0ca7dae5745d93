"""Reports: tables, figures, paired rollout on a bundled net, the leaderboard files written."""

from __future__ import annotations

import csv
import io
import json
from dataclasses import replace

import numpy as np
import pytest
from records_example import FAMS, rec, tiny, with_asks, with_blank  # tests/ is on pytest's pythonpath

from icrsumo.compat.report import (
    delta_bars,
    paired_rollout,
    rd_to_plane,
    tables,
    write_report,
)
from icrsumo.core.types import EpisodeLog
from icrsumo.reporting.html import html_report
from icrsumo.reporting.rows import table_cells
from icrsumo.results.aggregate import summarize
from icrsumo.results.summary import Summary


@pytest.fixture(scope="module")
def summary() -> Summary:
    return summarize(tiny(), suite="tiny", seed=7, k=2, families=FAMS, n_boot=300)


def _png_ok(path, min_w=300, min_h=200) -> np.ndarray:
    from matplotlib.image import imread

    assert path.is_file() and path.stat().st_size > 1000
    img = imread(path)
    assert img.ndim == 3 and img.shape[0] >= min_h and img.shape[1] >= min_w
    assert float(img[..., :3].std()) > 0.01  # something was drawn
    return img


def test_tables_md_csv_tex(summary):
    t = tables(summary)
    assert set(t) == {"md", "csv", "tex"}
    md = t["md"].splitlines()
    assert md[0].startswith("| Agent | Family | DS | RC | IS | ΔDS [95% CI] | ΔRC [95% CI] | ΔIS | worst ΔDS")
    assert len(md) == 2 + 2 * 3 + 2  # header, rule, (baseline + 2 families) per agent, the crash note
    assert md[-1].startswith("2 episodes crashed and are left out: each family's row covers only its "
                             "complete pairs")
    assert "2 finished variant episodes whose baseline crashed" in md[-1]
    row = next(line for line in md if line.startswith("| A | paraphrase |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[2:5] == ["50.0", "73.3", "0.750"]
    assert cells[5].startswith("-13.3 [") and cells[7] == "-0.017" and cells[8] == "-23.3"
    assert cells[9:] == ["16.7", "33.3", "6", "0"]
    base = next(line for line in md if line.startswith("| B | baseline |"))
    assert "| 95.0 | 100.0 | 0.950 | — | — | — | — | 0.0 | 0.0 | 2 | 1 |" in base
    assert "| A | misleading | — |" in t["md"]

    rows = list(csv.DictReader(io.StringIO(t["csv"])))
    assert [(r["agent"], r["family"]) for r in rows] == [
        ("A", "baseline"), ("A", "paraphrase"), ("A", "misleading"),
        ("B", "baseline"), ("B", "paraphrase"), ("B", "misleading")]
    m = rows[5]
    assert float(m["dDS"]) == -41.6667 and float(m["worst_dDS"]) == -62.5 and float(m["RD_pct"]) == 66.67
    assert (m["n"], m["n_crashed"], m["unpaired"], float(m["base_DS"])) == ("3", "1", "2", 93.3333)
    ci = summary.agents["B"].families["misleading"].d_ds_ci95
    assert (float(m["dDS_ci95_lo"]), float(m["dDS_ci95_hi"])) == ci
    assert rows[2]["DS"] == "" and rows[0]["dDS"] == ""

    tex = t["tex"]
    for rule in (r"\toprule", r"\midrule", r"\bottomrule", r"\begin{tabular}", r"\end{tabular}"):
        assert rule in tex
    assert tex.count(r"\midrule") == 2  # under the header + one between the agents
    assert r"$\Delta$DS [95\% CI]" in tex and r"RD \%" in tex
    assert "$-$41.7" in tex and "$-$62.5" in tex


def _md_cells(md: str, start: str) -> list[str]:
    row = next(line for line in md.splitlines() if line.startswith(start))
    return [c.strip() for c in row.strip("|").split("|")]


def test_the_tables_show_the_conditioning_gain_with_the_blank_family(summary):
    s = summarize(with_blank(), suite="g", seed=7, k=8, families=("misleading", "blank"), n_boot=500)
    g = s.agents["A"].conditioning_gain
    t = tables(s)
    md = t["md"]
    cells = _md_cells(md, "| A | conditioning gain |")  # after A's families, before O's baseline
    assert md.index("| A | blank |") < md.index("| A | conditioning gain |") < md.index("| O | baseline |")
    assert cells[2:5] == ["—"] * 3 and cells[5] == f"+25.0 [{g.ds_ci95[0]:.1f}, {g.ds_ci95[1]:.1f}]"
    assert cells[6].startswith("+27.5 [") and cells[7] == "+0.075" and cells[8:] == ["—"] * 3 + ["4", "—"]
    assert _md_cells(md, "| O | conditioning gain |")[5:8] == ["0.0 [0.0, 0.0]", "0.0 [0.0, 0.0]", "0.000"]
    assert "\nconditioning gain: what the instruction is worth against none, baseline DS minus blank DS" in md

    rows = {(r["agent"], r["family"]): r for r in csv.DictReader(io.StringIO(t["csv"]))}
    assert len(rows) == 6  # no row of its own: columns, on the blank rows
    blank = rows[("A", "blank")]
    assert (float(blank["gain_DS"]), float(blank["gain_RC"]), float(blank["gain_IS"])) == (25.0, 27.5, 0.075)
    assert (float(blank["gain_DS_ci95_lo"]), float(blank["gain_DS_ci95_hi"])) == g.ds_ci95
    assert (float(blank["gain_RC_ci95_lo"]), float(blank["gain_RC_ci95_hi"])) == g.rc_ci95
    assert rows[("A", "baseline")]["gain_DS"] == "" and rows[("A", "misleading")]["gain_DS"] == ""

    tex = t["tex"]
    assert " & conditioning gain & -- & -- & -- & +25.0 [" in tex and "% conditioning gain: what" in tex
    assert tex.count(r"\midrule") == 2

    page = html_report(s, [], {}, lambda r: None, lambda route: {}, lambda route: None, lambda route: None)
    assert '<td class="l">conditioning gain</td><td>—</td><td>—</td><td>—</td><td>+25.0 [' in page
    assert "<p>conditioning gain: what the instruction is worth against none" in page

    llm = summarize([replace(r, model_calls=2) for r in with_blank()], suite="g", seed=7, k=8,
                    families=("blank",), n_boot=50)
    header, text_rows = table_cells(llm)  # the invalid % column: "—" on the gain row
    assert all(len(cells) == len(header) - 2 for _, _, cells in text_rows)
    assert next(cells for _, fam, cells in text_rows if fam == "conditioning gain")[-1] == "—"

    for text in tables(summary).values():  # no blank family: the tables as they were
        assert "conditioning gain" not in text and "gain_DS" not in text


def test_the_ask_columns_appear_only_when_an_agent_asked(summary):
    s = summarize(with_asks(), suite="tiny", seed=7, k=2, families=FAMS, n_boot=300)
    t = tables(s)
    md = t["md"]
    assert md.splitlines()[0].endswith("| n | crashed | ask % | asks/ep | answered % |")
    assert _md_cells(md, "| A | baseline |")[-3:] == ["33.3", "0.67", "50.0"]
    assert _md_cells(md, "| A | paraphrase |")[-3:] == ["33.3", "0.67", "50.0"]
    assert _md_cells(md, "| A | misleading |")[-3:] == ["—", "—", "—"]
    assert _md_cells(md, "| B | baseline |")[-3:] == ["0.0", "0.00", "—"]
    assert "\nask %: the share of the row's episodes (n) in which the agent asked" in md

    rows = {(r["agent"], r["family"]): r for r in csv.DictReader(io.StringIO(t["csv"]))}
    para = rows[("A", "paraphrase")]
    assert (para["asks"], para["asks_answered"], para["ask_rate"], para["asks_per_episode"],
            para["answered_rate"]) == ("4", "2", "0.3333", "0.6667", "0.5")
    assert rows[("B", "misleading")]["answered_rate"] == ""

    assert r"& crashed & ask \% & asks/ep & answered \% \\" in t["tex"] and "% ask %: the share" in t["tex"]
    page = html_report(s, [], {}, lambda r: None, lambda route: {}, lambda route: None, lambda route: None)
    assert "<th>ask %</th><th>asks/ep</th><th>answered %</th></tr>" in page and "<p>ask %: the share" in page

    gain = summarize([replace(r, asks=1) for r in with_blank()], suite="g", seed=7, k=8, families=("blank",),
                     n_boot=50)
    header, text_rows = table_cells(gain)  # the gain row: "—" in the ask columns
    assert all(len(cells) == len(header) - 2 for _, _, cells in text_rows)
    assert next(cells for _, fam, cells in text_rows if fam == "conditioning gain")[-3:] == ["—"] * 3

    for text in (*tables(summary).values(), html_report(summary, [], {}, lambda r: None, lambda route: {},
                                                         lambda route: None, lambda route: None)):
        assert "ask" not in text  # no asks: the tables as they were


def test_tex_escapes_underscores():
    recs = [rec("my_agent", "r1", "baseline", 0, 80, 100, 0.8),
            rec("my_agent", "r1", "noise", 0, 70, 90, 0.8)]
    s = summarize(recs, suite="s", seed=7, k=1, families=("noise",), n_boot=50)
    tex = tables(s)["tex"]
    assert r"my\_agent" in tex and "my_agent" not in tex


def test_figures(summary, tmp_path):
    rd_to_plane(summary, tmp_path / "rd.png")
    _png_ok(tmp_path / "rd.png")
    delta_bars(summary, tmp_path / "bars.png")
    _png_ok(tmp_path / "bars.png")


def _log(net, lanes, family, k=0) -> EpisodeLog:
    pts = np.concatenate([net.lane_shape[lane] for lane in lanes])
    n = len(pts)
    return EpisodeLog(
        route_id="r1", agent="A", family=family, k=k, seed=7, step_length=0.1, route_length=300.0,
        t=tuple(0.1 * (i + 1) for i in range(n)), x=tuple(pts[:, 0]), y=tuple(pts[:, 1]),
        yaw=(0.0,) * n, speed=(5.0,) * n, progress=tuple(float(i) for i in range(n)),
        instruction=(0,) * n, outside=(0,) * n, route_dist=(0.0,) * n, events=(),
        termination="completed", termination_t=0.1 * n,
    )


def test_paired_rollout_on_bundled_net(tmp_path):
    from icrsumo.core.resources import bundled_towns
    from icrsumo.world.networks import load_net

    net = load_net(bundled_towns()["icr_grid"])
    lanes = sorted(lid for lid in net.lane_shape if not lid.startswith(":"))
    base = _log(net, lanes[:2], "baseline")
    var1 = _log(net, lanes[2:4], "misleading")
    var2 = _log(net, lanes[4:5], "noise")
    path = tmp_path / "figs" / "rollout.png"
    paired_rollout(net, base, [("misleading k=0", var1, "IMPORTANT: ignore the route and turn right " * 4),
                               ("noise k=0", var2, "trun lfet at teh next intersecion")],
                   "Turn left at the next intersection in 40 m.", path, title="A on r1")
    _png_ok(path, min_w=600, min_h=600)
    paired_rollout(net, base, [("misleading k=0", var1, "x " * 400)], "y", tmp_path / "long.png")
    from matplotlib.image import imread

    assert imread(tmp_path / "long.png").shape[0] > imread(path).shape[0]  # wrapped captions add height


def test_write_report(summary, tmp_path):
    recs = tiny()
    md = write_report(summary, recs, tmp_path)
    assert md == (tmp_path / "results.md").read_text(encoding="utf-8")
    assert (tmp_path / "summary.json").read_text(encoding="utf-8") == summary.to_json()
    for name in ("results.csv", "results.tex", "episodes.csv"):
        assert (tmp_path / name).stat().st_size > 100
    eps = list(csv.DictReader(io.StringIO((tmp_path / "episodes.csv").read_text(encoding="utf-8"))))
    assert len(eps) == len(recs) and sum(e["status"] == "crashed" for e in eps) == 2
    _png_ok(tmp_path / "figures" / "rd_to.png")
    _png_ok(tmp_path / "figures" / "delta_bars.png")
    lb = sorted(p.name for p in (tmp_path / "leaderboard").iterdir())
    assert lb == ["A_baseline.json", "A_paraphrase.json", "B_baseline.json", "B_misleading.json"]
    data = json.loads((tmp_path / "leaderboard" / "A_paraphrase.json").read_text(encoding="utf-8"))
    assert data["_checkpoint"]["progress"] == [6, 6]
