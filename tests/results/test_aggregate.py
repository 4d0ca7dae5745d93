"""ICR-Drive aggregation: hand-computed means and deltas, crashes, order independence, bootstrap."""

from __future__ import annotations

import random

import numpy as np
import pytest
from records_example import FAMS, GAINS_A, rec, tiny, with_asks, with_blank  # tests/ is on the pythonpath

from icrsumo.core.types import EpisodeRecord
from icrsumo.results.aggregate import FAMILIES, bootstrap_ci, episode_table, summarize
from icrsumo.results.summary import AskCounts, BaselineStats, EpisodeCounts, Flips


def test_hand_computed_tiny_example():
    s = summarize(tiny(), suite="tiny", seed=7, k=2, families=FAMS, n_boot=500)
    assert (s.suite, s.seed, s.k) == ("tiny", 7, 2)
    assert s.episodes == EpisodeCounts(done=16, crashed=2)
    assert list(s.agents) == ["A", "B"]
    assert list(s.agents["A"].families) == ["paraphrase", "misleading"]

    a_base = s.agents["A"].baseline
    assert a_base == BaselineStats(ds=63.3333, rc=86.6667, is_=0.766667, rd=0.0, to=0.3333, n=3, n_crashed=0)
    p = s.agents["A"].families["paraphrase"]
    assert (p.ds, p.rc, p.is_) == (50.0, 73.3333, 0.75)
    assert (p.d_ds, p.d_rc, p.d_is) == (-13.3333, -13.3333, -0.016667)
    assert p.worst_d_ds == -23.3333  # mean(-40, -30, 0)
    assert (p.rd, p.to, p.n, p.n_routes) == (0.1667, 0.3333, 6, 3)
    assert p.baseline_done_variant_failed == 1  # r1 only: r2's baseline timed out

    # B: baseline r2 and misleading r1/k1 crashed -> out of every mean; r2's variants are
    # unpaired and left out too: every number covers the complete pairs r1/k0, r3/k0, r3/k1
    b_base = s.agents["B"].baseline
    assert (b_base.ds, b_base.rc, b_base.is_) == (95.0, 100.0, 0.95)
    assert (b_base.n, b_base.n_crashed) == (2, 1)
    m = s.agents["B"].families["misleading"]
    assert (m.ds, m.rc, m.is_, m.n) == (51.6667, 56.6667, 0.933333, 3)  # (20+90+45)/3, ...
    assert (m.base_ds, m.base_rc, m.base_is) == (93.3333, 100.0, 0.933333)  # (100+90+90)/3
    assert (m.d_ds, m.d_rc, m.d_is) == (-41.6667, -43.3333, 0.0)
    assert m.d_ds == pytest.approx(m.ds - m.base_ds, abs=1e-3)  # the means and the delta agree
    assert m.worst_d_ds == -62.5  # mean(-80, -45)
    assert (m.rd, m.to, m.n_routes) == (0.6667, 0.0, 2)
    assert (m.n_crashed, m.unpaired, m.n_pairs) == (1, 2, 3)
    assert m.baseline_done_variant_failed == 2

    # a family without episodes: None, never NaN
    empty = s.agents["A"].families["misleading"]
    assert empty.n == 0 and empty.ds is None and empty.d_ds is None and empty.d_ds_ci95 is None
    assert empty.rd is None and empty.baseline_done_variant_failed == 0
    text = s.to_json()  # allow_nan=False: raises on NaN
    assert "NaN" not in text


def test_schema_keys():
    s = summarize(tiny(), suite="tiny", seed=7, k=2, families=FAMS, n_boot=100).to_dict()
    assert {"suite", "seed", "k", "episodes", "agents"} <= set(s)
    assert set(s["episodes"]) == {"done", "crashed"}
    for a in s["agents"].values():
        assert set(a) == {"baseline", "families"}
        assert set(a["baseline"]) == {"DS", "RC", "IS", "RD", "TO", "n", "n_crashed"}
        for f in a["families"].values():
            assert {"DS", "RC", "IS", "dDS", "dRC", "dIS", "worst_dDS", "dDS_ci95", "dRC_ci95", "RD", "TO",
                    "n", "n_routes", "baseline_done_variant_failed", "n_crashed", "unpaired", "base_DS",
                    "base_RC", "base_IS"} <= set(f)
    ci = s["agents"]["A"]["families"]["paraphrase"]["dDS_ci95"]
    assert isinstance(ci, list) and len(ci) == 2 and all(isinstance(v, float) for v in ci)
    assert isinstance(s["agents"]["A"]["baseline"]["n"], int)
    default = summarize([], suite="x", seed=1, k=8)
    assert default.agents == {} and default.episodes == EpisodeCounts(0, 0)
    assert default.families == FAMILIES


def test_order_independence_byte_identical():
    recs = tiny()
    ref = summarize(recs, suite="tiny", seed=7, k=2, families=FAMS).to_json()
    rnd = random.Random(3)
    for _ in range(3):
        shuffled = recs[:]
        rnd.shuffle(shuffled)
        assert summarize(shuffled, suite="tiny", seed=7, k=2, families=FAMS).to_json() == ref
    assert episode_table(list(reversed(recs))) == episode_table(recs)


def test_duplicates_and_foreign_families():
    recs = tiny()
    with pytest.raises(ValueError, match="duplicate"):
        summarize(recs + [recs[0]], suite="t", seed=7, k=2, families=FAMS)
    # records of families not asked for are ignored (and not counted)
    s = summarize(recs, suite="t", seed=7, k=2, families=("paraphrase",))
    assert s.episodes == EpisodeCounts(done=11, crashed=1)
    assert list(s.agents["B"].families) == ["paraphrase"]


def _generated(n_routes: int, deltas, seed: int = 0) -> list[EpisodeRecord]:
    """Baseline DS/RC drawn per route; variant k of each route = baseline + deltas(route, k)."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n_routes):
        route = f"route_{i:03d}"
        b_ds, b_rc = float(rng.uniform(40, 90)), float(rng.uniform(60, 100))
        out.append(rec("A", route, "baseline", 0, b_ds, b_rc, 0.9))
        for k in range(3):
            d = float(deltas(rng, i, k))
            out.append(rec("A", route, "noise", k, b_ds + d, b_rc + d / 2, 0.9))
    return out


def test_bootstrap_constant_delta_gives_zero_width():
    for n in (3, 20):
        s = summarize(_generated(n, lambda rng, i, k: -12.5), suite="g", seed=7, k=3, families=("noise",))
        f = s.agents["A"].families["noise"]
        assert f.d_ds == -12.5 and f.worst_d_ds == -12.5
        assert f.d_ds_ci95 == (-12.5, -12.5) and f.d_rc_ci95 == (-6.25, -6.25)


def test_bootstrap_contains_estimate_deterministic_and_shrinks():
    def noisy(rng, i, k):
        return -10.0 + rng.normal(0.0, 15.0)

    widths = []
    for n in (5, 80):
        recs = _generated(n, noisy, seed=11)
        s1 = summarize(recs, suite="g", seed=7, k=3, families=("noise",))
        s2 = summarize(recs, suite="g", seed=7, k=3, families=("noise",))
        assert s1.to_json() == s2.to_json()
        f = s1.agents["A"].families["noise"]
        for d, ci in ((f.d_ds, f.d_ds_ci95), (f.d_rc, f.d_rc_ci95)):
            assert ci[0] <= d <= ci[1]
        widths.append(f.d_ds_ci95[1] - f.d_ds_ci95[0])
        other = summarize(recs, suite="g", seed=7, k=3, families=("noise",), boot_seed=99)
        assert other.agents["A"].families["noise"].d_ds_ci95 != f.d_ds_ci95
    assert widths[1] < widths[0] / 2


def test_bootstrap_ci_function():
    assert bootstrap_ci(np.zeros(0), n_boot=10, seed=1) is None
    vals = np.arange(10.0)
    ci = bootstrap_ci(vals, n_boot=4000, seed=5)
    assert ci.shape == (2,) and ci[0] < 4.5 < ci[1]
    two = bootstrap_ci(np.column_stack([vals, 2 * vals]), n_boot=4000, seed=5)
    assert two.shape == (2, 2) and np.allclose(two[:, 1], 2 * two[:, 0])


def test_episode_table_rows():
    rows = episode_table(tiny())
    assert len(rows) == 18
    keys = [(r["agent"], r["route_id"], r["family"], r["k"], r["seed"]) for r in rows]
    assert keys == sorted(keys)
    crashed = [r for r in rows if r["status"] == "crashed"]
    assert len(crashed) == 2 and crashed[0]["message"] == "boom"
    r = rec("A", "r9", "noise", 1, 30, 50, 0.42, "RD",
            infractions=(("collision_vehicle", 0.6), ("red_light", 0.7)))
    row = episode_table([r])[0]
    assert row["infractions"] == "collision_vehicle:0.6;red_light:0.7" and row["n_infractions"] == 2
    assert row["is"] == 0.42 and row["termination"] == "route_deviation"


def test_reviewer_statistics_by_hand():
    s = summarize(tiny(), suite="tiny", seed=7, k=2, families=FAMS, n_boot=200)
    p = s.agents["A"].families["paraphrase"]
    # paired baseline means: DS (80+80+60+60+50+50)/6, RC (100+100+60+60+100+100)/6
    assert p.pdr_ds == round(13.3333333 / 63.3333333, 4)
    assert p.pdr_rc == round(13.3333333 / 86.6666667, 4)
    assert p.flips == Flips(lost=1, gained=0)  # r1 k1: done -> RD; r2 was TO on both sides
    # per-route mean dDS: r1 -25, r2 -15, r3 0 (dropped): exact two-sided Wilcoxon, n = 2 -> 0.5
    assert (p.p_value_raw, p.p_value) == (0.5, 0.5)
    m = s.agents["B"].families["misleading"]
    assert m.pdr_ds == round(41.6666667 / 93.3333333, 4)  # pairs r1k0, r3k0, r3k1
    assert m.flips == Flips(lost=2, gained=0)
    # an agent without a family's episodes has no test there, and Holm skips it
    assert s.agents["A"].families["misleading"].p_value is None


def test_a_family_that_changes_nothing_has_p_one_and_no_flips():
    recs = [rec("oracle", f"r{i}", fam, k, 90, 100, 0.9) for i in range(12)
            for fam, k in [("baseline", 0), ("misleading", 0), ("misleading", 1)]]
    b = summarize(recs, suite="x", seed=7, k=2, families=("misleading",), n_boot=100).agents["oracle"]
    m = b.families["misleading"]
    assert (m.p_value, m.pdr_ds, m.flips) == (1.0, 0.0, Flips(0, 0))


def test_a_consistent_drop_is_significant_and_gains_are_counted():
    recs = []
    for i in range(12):
        recs.append(rec("A", f"r{i}", "baseline", 0, 90, 100, 0.9, "done" if i else "RD"))
        recs.append(rec("A", f"r{i}", "misleading", 0, 40 + i, 50, 0.9, "RD" if i else "done"))
        recs.append(rec("A", f"r{i}", "noise", 0, 90 - (i % 2), 100, 0.9))
    fams = ("noise", "misleading")
    s = summarize(recs, suite="x", seed=7, k=1, families=fams, n_boot=100).agents["A"].families
    assert s["misleading"].p_value_raw < 0.001 and s["misleading"].flips == Flips(lost=11, gained=1)
    assert s["noise"].p_value_raw > 0.01
    assert list(fams) == list(s)


def test_holm_bonferroni():
    from icrsumo.results.aggregate import holm

    assert holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06])
    assert holm([0.5, None, 0.9]) == [1.0, None, 1.0]  # 2 x 0.5, then max(1.0, 1 x 0.9)
    assert holm([]) == []


def test_conditioning_gain_is_baseline_minus_blank_paired_on_route_and_seed():
    s = summarize(with_blank(), suite="g", seed=7, k=8, families=("misleading", "blank"), n_boot=500)
    g = s.agents["A"].conditioning_gain
    gains = np.asarray(GAINS_A)  # r5's crashed blank and r1's seed-8 blank are left out
    assert (g.ds, g.rc, g.is_, g.n, g.n_routes) == (25.0, 27.5, 0.075, 4, 4)
    expected = bootstrap_ci(gains[:, :2], n_boot=500, seed=2026)  # the bootstrap of baseline − blank
    assert g.ds_ci95 == (round(expected[0, 0], 4), round(expected[1, 0], 4))
    assert g.rc_ci95 == (round(expected[0, 1], 4), round(expected[1, 1], 4))
    assert g.ds_ci95[0] < g.ds < g.ds_ci95[1]
    blank = s.agents["A"].families["blank"]  # the blank row's Δ, the sign turned
    assert (blank.d_ds, blank.unpaired, blank.n_crashed) == (-25.0, 1, 1)
    again = summarize(reversed(with_blank()), suite="g", seed=7, k=8, families=("blank", "misleading"),
                      n_boot=500)
    assert again.agents["A"].conditioning_gain == g  # reproducible, whatever the order
    other = summarize(with_blank(), suite="g", seed=7, k=8, families=("blank",), n_boot=500, boot_seed=1)
    assert other.agents["A"].conditioning_gain.ds_ci95 != g.ds_ci95  # seeded by boot_seed

    o = s.agents["O"].conditioning_gain  # blind to language: exactly 0, never -0.0
    assert (o.ds, o.ds_ci95, o.rc_ci95, o.is_, o.n) == (0.0, (0.0, 0.0), (0.0, 0.0), 0.0, 4)
    assert "-0.0" not in str(s.to_dict()["agents"]["O"]["conditioning_gain"])
    assert s.to_dict()["agents"]["A"]["conditioning_gain"] == {
        "DS": 25.0, "RC": 27.5, "IS": 0.075, "DS_ci95": list(g.ds_ci95), "RC_ci95": list(g.rc_ci95), "n": 4,
        "n_routes": 4}


def test_without_the_blank_family_there_is_no_conditioning_gain():
    s = summarize(with_blank(), suite="g", seed=7, k=8, families=("misleading",), n_boot=100)
    assert all(a.conditioning_gain is None for a in s.agents.values()) and not s.has_conditioning_gain
    assert all(set(a) == {"baseline", "families"} for a in s.to_dict()["agents"].values())
    none = summarize(tiny(), suite="tiny", seed=7, k=2, families=(*FAMS, "blank"), n_boot=100)
    g = none.agents["A"].conditioning_gain  # the blank family run, but no blank episode: no pair
    assert (g.ds, g.rc, g.is_, g.ds_ci95, g.rc_ci95, g.n, g.n_routes) == (None, None, None, None, None, 0, 0)


def test_asks_are_counted_per_row_over_its_episodes():
    s = summarize(with_asks(), suite="tiny", seed=7, k=2, families=FAMS, n_boot=100)
    a, b = s.agents["A"], s.agents["B"]
    assert s.has_asks
    assert a.baseline.asking == AskCounts(2, 1, 0.3333, 0.6667, 0.5)  # 1 of 3 episodes asked, twice
    assert a.families["paraphrase"].asking == AskCounts(4, 2, 0.3333, 0.6667, 0.5)  # 2 of 6 pairs
    assert a.families["misleading"].asking == AskCounts(0, 0, None, None, None)  # no episode
    # B never asked in a pair (its ask is on an unpaired episode): zeros, on every row of the run
    assert b.baseline.asking == AskCounts(0, 0, 0.0, 0.0, None)
    assert b.families["misleading"].asking == AskCounts(0, 0, 0.0, 0.0, None)
    doc = s.to_dict()["agents"]["A"]
    assert {k: doc["families"]["paraphrase"][k] for k in ("asks", "asks_answered", "ask_rate",
                                                           "asks_per_episode", "answered_rate")} == {
        "asks": 4, "asks_answered": 2, "ask_rate": 0.3333, "asks_per_episode": 0.6667, "answered_rate": 0.5}


def test_a_run_without_asks_has_no_ask_counts():
    s = summarize(tiny(), suite="tiny", seed=7, k=2, families=FAMS, n_boot=100)
    assert not s.has_asks and all(b.asking is None for _, _, b in s.rows())
    assert "ask" not in s.to_json()
