"""guard.json's numbers from stored records (pure): block rates, Δ with and without the guard,
the shrink of the misleading Δ, flips prevented and caused, the paired loss test, the targets."""

from __future__ import annotations

from icrsumo.core.types import EpisodeRecord
from icrsumo.core.vocab import EpisodeStatus
from icrsumo.guards.text import TextGuard
from icrsumo.instructions.banks import load_banks
from icrsumo.reporting.guard import guard_markdown
from icrsumo.results.aggregate import summarize
from icrsumo.results.guards import guard_doc, split_row, template_number, text_holdout


def rec(agent, route, family, k, ds, checked=0, blocked=0):
    done = ds == 100.0
    return EpisodeRecord(agent, route, family, k, 1, EpisodeStatus.DONE, ds=ds, rc=ds, is_=1.0,
                         termination="route_completed" if done else "route_deviation",
                         termination_class="done" if done else "RD", guard_checked=checked,
                         guard_blocked=blocked)


def records():
    out = []
    for r in ("r1", "r2", "r3", "r4"):
        out += [rec("a", r, "baseline", 0, 100.0), rec("a+guard:plan", r, "baseline", 0, 100.0, 2, 0)]
        for k in (0, 1):
            out += [rec("a", r, "misleading", k, 40.0), rec("a+guard:plan", r, "misleading", k, 100.0, 2, 2),
                    rec("a", r, "paraphrase", k, 100.0),
                    rec("a+guard:plan", r, "paraphrase", k, 100.0 if (r, k) != ("r1", 0) else 40.0, 2,
                        int((r, k) == ("r1", 0)))]
    return out


def test_rows_block_rates_shrink_flips_and_targets():
    recs = records()
    summary = summarize(recs, suite="t", seed=1, k=2, families=("paraphrase", "misleading"))
    doc = guard_doc(summary, recs)
    row = doc["rows"]["a+guard:plan"]
    assert (row["agent"], row["guard"], row["unguarded_in_run"]) == ("a", "plan", True)
    mis, para = row["families"]["misleading"], row["families"]["paraphrase"]
    assert (mis["checked"], mis["blocked"], mis["block_rate"]) == (16, 16, 1.0)
    assert mis["guarded"]["dDS"] == 0.0 and mis["unguarded"]["dDS"] == -60.0 and mis["dDS_shrink"] == 1.0
    assert mis["flips"] == {"prevented": 8, "caused": 0} and mis["loss"]["mean_dDS_vs_unguarded"] == 60.0
    assert para["block_rate"] == 0.0625 and para["flips"] == {"prevented": 0, "caused": 1}
    assert para["loss"]["mean_dDS_vs_unguarded"] == -7.5 and not para["loss"]["significant_loss"]  # 1 route
    g = doc["guards"]["plan"]
    assert g["detection"] == 1.0 and g["false_blocks"] == round(1 / 24, 4)
    t = g["targets"]
    assert t["detection"]["met"] and not t["false_blocks"]["met"] and t["dDS_shrink"]["met"]
    assert t["no_significant_loss"]["met"]
    md = guard_markdown(doc)
    assert "| plan | 100.0 % | 4.2 % |" in md and "| misleading | 16/16 (100.0 %) |" in md
    assert guard_doc(summarize([r for r in recs if r.agent == "a"], suite="t", seed=1, k=2,
                               families=("misleading",)), recs) is None


def test_names_and_template_numbers():
    assert split_row("bev+guard:plan") == ("bev", "plan") and split_row("bev") is None
    assert split_row("x+guard:y+guard:z") == ("x+guard:y", "z")
    assert template_number("M.left.p07") == 7 and template_number("keep") is None


def test_the_text_guard_is_reported_on_the_templates_it_was_not_written_from():
    doc = text_holdout(TextGuard(), load_banks())
    assert doc["tuning"]["templates"] == doc["held_out"]["templates"] == 96
    assert doc["tuning"]["detection"] == 1.0           # its cues were written from these
    assert 0.5 <= doc["held_out"]["detection"] <= 1.0  # the finding (0.75 when written)
    assert doc["paraphrase_bank"]["block_rate"] == 0.0


def test_repairs_are_counted_with_what_they_bought_and_keep_rows_are_as_before():
    """A navigator row (``a+guard:plan+navigator``): its repaired instructions are blocked too,
    counted per family, with the repaired episodes' DS / RC beside the unguarded agent's on the
    same pairs; the plan guard under repair has its own entry and targets. A keep row without
    repairs has the document it always had."""
    from dataclasses import replace

    recs = [r for r in records() if r.agent == "a"]
    for r in records():
        if r.agent == "a+guard:plan":
            repaired = r.guard_blocked if (r.route_id, r.k) != ("r2", 1) else 0   # one episode passed all
            recs.append(replace(r, agent="a+guard:plan+navigator", guard_repaired=repaired))
    summary = summarize(recs, suite="t", seed=1, k=2, families=("paraphrase", "misleading"))
    doc = guard_doc(summary, recs)
    row = doc["rows"]["a+guard:plan+navigator"]
    assert (row["agent"], row["guard"], row["on_block"]) == ("a", "plan+navigator", "navigator")
    mis = row["families"]["misleading"]
    assert (mis["checked"], mis["blocked"]) == (16, 16)
    assert mis["repairs"] == {"repaired": 14, "episodes": 7, "pairs": 7, "DS": 100.0, "DS_unguarded": 40.0,
                              "RC": 100.0, "RC_unguarded": 40.0}
    assert row["families"]["baseline"]["repairs"] == {"repaired": 0, "episodes": 0, "pairs": 0, "DS": None,
                                                      "DS_unguarded": None, "RC": None, "RC_unguarded": None}
    g = doc["guards"]["plan+navigator"]
    assert g["repaired"] == {"baseline": 0, "paraphrase": 1, "misleading": 14}
    assert g["targets"]["dDS_shrink"]["target"] == 0.9 and g["targets"]["dDS_shrink"]["met"]
    md = guard_markdown(doc)
    assert "| repaired | repaired episodes: DS guarded / unguarded (pairs) |" in md
    assert "| 14 in 7 episodes | 100.0 / 40.0 (7) |" in md
    from icrsumo.reporting.guard import guard_note

    assert "Guard plan+navigator: blocked 16/16 (100.0 %) misleading instructions (detection) and 1/24 " \
           "(4.2 %) goal-preserving ones (false blocks); repaired 15 blocked instructions" \
           in guard_note(doc)
    keep = guard_doc(summarize(records(), suite="t", seed=1, k=2, families=("paraphrase", "misleading")),
                     records())
    assert "on_block" not in keep["rows"]["a+guard:plan"] and "repaired" not in keep["guards"]["plan"]
    assert all("repairs" not in f for f in keep["rows"]["a+guard:plan"]["families"].values())
    assert "repaired" not in guard_markdown(keep)


def test_goal_kept_delivery_families_count_as_false_blocks_and_correction_stays_apart():
    recs = []
    for r in ("r1", "r2"):
        recs += [rec("a", r, "baseline", 0, 100.0), rec("a+guard:plan", r, "baseline", 0, 100.0, 2, 0)]
        for fam, blocked in (("timing", 1), ("notice", 0), ("correction", 2)):
            recs += [rec("a", r, fam, 0, 100.0), rec("a+guard:plan", r, fam, 0, 100.0, 2, blocked)]
    doc = guard_doc(summarize(recs, suite="t", seed=1, k=1, families=("timing", "notice", "correction")),
                    recs)
    g = doc["guards"]["plan"]
    # baseline 0/4, timing 2/4, notice 0/4 -> 2/12; correction's 4/4 is not a false block
    assert g["false_blocks"] == round(2 / 12, 4) and g["block_rate"]["correction"] == 1.0
    assert "timing, distance, notice" in guard_markdown(doc)
