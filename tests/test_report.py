"""Reports: tables, figures, paired rollout on a bundled net, Leaderboard 1.0 checkpoints."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest
from records_example import FAMS, rec, tiny  # tests/ is on pytest's pythonpath

from icrsumo.aggregate import summarize
from icrsumo.fsio import dumps_json
from icrsumo.report import (
    delta_bars,
    leaderboard_checkpoint,
    paired_rollout,
    rd_to_plane,
    tables,
    write_report,
)
from icrsumo.types import EpisodeLog, EpisodeRecord


@pytest.fixture(scope="module")
def summary() -> dict:
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
    ci = summary["agents"]["B"]["families"]["misleading"]["dDS_ci95"]
    assert (float(m["dDS_ci95_lo"]), float(m["dDS_ci95_hi"])) == tuple(ci)
    assert rows[2]["DS"] == "" and rows[0]["dDS"] == ""

    tex = t["tex"]
    for rule in (r"\toprule", r"\midrule", r"\bottomrule", r"\begin{tabular}", r"\end{tabular}"):
        assert rule in tex
    assert tex.count(r"\midrule") == 2  # under the header + one between the agents
    assert r"$\Delta$DS [95\% CI]" in tex and r"RD \%" in tex
    assert "$-$41.7" in tex and "$-$62.5" in tex


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
    from icrsumo.networks import load_net
    from icrsumo.resources import bundled_towns

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


def test_leaderboard_checkpoint():
    recs = tiny() + [rec("B", "r4", "misleading", 0, 30, 100, 0.3,
                         infractions=(("collision_vehicle", 0.6), ("red_light", 0.7),
                                      ("outside_route_lanes", 0.3 / 0.42)))]
    cp = leaderboard_checkpoint(recs, "B", "misleading")
    assert set(cp) == {"_checkpoint", "entry_status", "eligible", "sensors", "values", "labels"}
    # r1 k1 crashed in the simulator: the leaderboard stops there with 'Crashed', not eligible
    assert cp["entry_status"] == "Crashed" and cp["eligible"] is False and cp["sensors"] == []
    c = cp["_checkpoint"]
    assert set(c) == {"global_record", "progress", "records"}
    assert c["progress"] == [7, 7] and len(c["records"]) == 7
    recs_by_id = {r["route_id"]: r for r in c["records"]}
    assert [r["index"] for r in c["records"]] == list(range(7))
    first = c["records"][0]
    assert set(first) == {"route_id", "index", "status", "infractions", "scores", "meta"}
    assert set(first["infractions"]) == {
        "collisions_layout", "collisions_pedestrian", "collisions_vehicle", "outside_route_lanes",
        "red_light", "route_dev", "route_timeout", "stop_infraction", "vehicle_blocked"}
    assert set(first["scores"]) == {"score_route", "score_penalty", "score_composed"}
    assert set(first["meta"]) == {"route_length", "duration_game", "duration_system"}

    r1 = recs_by_id["RouteScenario_r1_misleading_0"]
    assert r1["status"] == "Failed - Agent deviated from the route"
    assert r1["infractions"]["route_dev"] == ["Agent deviated from the route"]
    assert recs_by_id["RouteScenario_r1_misleading_1"]["status"] == "Failed - Simulation crashed"
    assert recs_by_id["RouteScenario_r2_misleading_1"]["status"] == "Failed - Agent timed out"
    assert recs_by_id["RouteScenario_r2_misleading_1"]["infractions"]["route_timeout"] == ["Route timeout."]
    assert recs_by_id["RouteScenario_r3_misleading_0"]["status"] == "Completed"
    r4 = recs_by_id["RouteScenario_r4_misleading_0"]
    assert r4["scores"] == {"score_route": 100.0, "score_penalty": 0.3, "score_composed": 30.0}
    assert len(r4["infractions"]["collisions_vehicle"]) == 1 and len(r4["infractions"]["red_light"]) == 1
    # the outside-lanes entry comes from the stored infraction (1 - 0.3 / 0.42 = 28.57 %) ...
    assert "28.57%" in r4["infractions"]["outside_route_lanes"][0]
    # ... never from IS arithmetic: r3 k0 has IS 0.9 but no such infraction, so no entry
    assert recs_by_id["RouteScenario_r3_misleading_0"]["infractions"]["outside_route_lanes"] == []

    g = c["global_record"]
    assert g["index"] == -1 and g["route_id"] == -1 and g["status"] == "Failed"
    assert set(g) >= {"route_id", "index", "status", "infractions", "scores", "meta"}
    # means over every route, the crashed one (0) included
    assert g["scores"]["score_composed"] == pytest.approx((20 + 0 + 10 + 50 + 90 + 45 + 30) / 7)
    # rates: sum over routes of count / max(RC / 100 x 0.5 km, 0.001): route deviations on r1 k0
    # (RC 20: 1 / 0.1), r2 k0 (RC 10: 1 / 0.05), r3 k1 (RC 50: 1 / 0.25); r4's collision (RC 100)
    assert g["infractions"]["route_dev"] == pytest.approx(10 + 20 + 4, abs=1e-6)
    assert g["infractions"]["collisions_vehicle"] == pytest.approx(2.0, abs=1e-6)
    assert ["RouteScenario_r1_misleading_1", 1, "Failed - Simulation crashed"] in g["meta"]["exceptions"]
    assert g["meta"]["total_length"] == 3000.0 and g["meta"]["duration_game"] == 360.0  # crashed: 0
    assert g["meta"]["duration_system"] == -1
    assert len(cp["values"]) == len(cp["labels"]) == 12
    assert cp["labels"][0] == "Avg. driving score"
    assert cp["values"][0] == f"{g['scores']['score_composed']:.3f}"
    json.loads(dumps_json(cp))  # serialisable, no NaN

    # without the simulator crash: deviations and timeouts name the agent
    ok = [r for r in recs if r.status == "done"]
    assert leaderboard_checkpoint(ok, "B", "misleading")["entry_status"] == "Finished with agent errors"
    done = [rec("B", "r3", "misleading", 0, 90, 100, 0.9)]
    assert leaderboard_checkpoint(done, "B", "misleading")["entry_status"] == "Finished"

    blocked = [EpisodeRecord("X", "r", "noise", 0, 1, "done", termination="agent_blocked",
                             termination_class="TO", is_=1.0)]
    cb = leaderboard_checkpoint(blocked, "X", "noise")["_checkpoint"]["records"][0]
    assert cb["status"] == "Failed - Agent got blocked" and len(cb["infractions"]["vehicle_blocked"]) == 1


def test_leaderboard_2_results_file():
    from icrsumo.report import leaderboard_checkpoint_lb2

    recs = [rec("B", "r1", "misleading", 0, 100, 100, 1.0),                       # Perfect
            rec("B", "r2", "misleading", 0, 85, 100, 0.85, infractions=(("min_speed", 0.85),)),
            rec("B", "r3", "misleading", 0, 40, 50, 0.8, "RD",
                infractions=(("outside_route_lanes", 0.8),), outside_m=50.0),
            rec("B", "r4", "misleading", 0, status="crashed")]
    cp = leaderboard_checkpoint_lb2(recs, "B", "misleading")
    rs = cp["_checkpoint"]["records"]
    assert [r["status"] for r in rs] == ["Perfect", "Completed", "Failed - Agent deviated from the route",
                                         "Failed - Simulation crashed"]
    assert rs[1]["infractions"]["min_speed_infractions"] == [
        "Average speed is 50.00% of the surrounding traffic's one"]
    # the metres off the lanes, where 2.0's global statistics read them
    assert rs[2]["infractions"]["outside_route_lanes"][0].split(" ")[8] == "50.000"
    g = cp["_checkpoint"]["global_record"]
    assert g["status"] == "Failed"
    assert g["scores_mean"]["score_composed"] == round((100 + 85 + 40 + 0) / 4, 6)
    # pooled: counts over the km driven (0.5 + 0.5 + 0.25 + 0 km); outside lanes in km
    assert g["infractions"]["route_dev"] == round(1 / 1.25, 3)
    assert g["infractions"]["outside_route_lanes"] == 0.05
    assert len(cp["values"]) == len(cp["labels"]) == 15
    assert cp["entry_status"] == "Crashed" and cp["eligible"] is False


def test_write_report(summary, tmp_path):
    recs = tiny()
    md = write_report(summary, recs, tmp_path)
    assert md == (tmp_path / "results.md").read_text(encoding="utf-8")
    assert (tmp_path / "summary.json").read_text(encoding="utf-8") == dumps_json(summary)
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
