"""Decision-level attribution over an evaluation's episodes (pure: decisions in, dicts out).

Per agent and family (the baseline included): the decisions' outcomes (``decisions``: counts of
followed_route / followed_text / other / not_reached), ``compliance`` (of the reached decisions
whose text names another branch than the route's, the share where the ego took the text's:
override susceptibility; None when there is none), ``adherence`` (of the reached decisions,
the share passed on the route) and ``confusion`` (instructed intent -> executed branch ->
count, reached decisions only); for an agent that asks a language model, ``answers``
(instructed intent -> the maneuver the model answered when the instruction came -> count):
what the model understood, apart from what the car then did.

First-divergence attribution: every variant episode that failed (its termination class not
done) where its route's baseline completed is a *flip*; its row names the decision at which
it left the route (:func:`icrsumo.results.decisions.divergence`) and the instruction active there (id,
text, template or noise-operation id). Templates are ranked by the flips they were active at,
beside how often they were active at a reached decision (their flip rate).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from icrsumo.core.types import EpisodeRecord
from icrsumo.core.vocab import DecisionOutcome, Family

from .decisions import Decision, divergence
from .summary import DecisionStats

#: an episode's key in the store: (agent, route_id, family, k, seed)
Key = tuple[str, str, str, int, int]


def episode_key(r: EpisodeRecord) -> Key:
    """The key of episode ``r`` in the decisions' mappings: (agent, route_id, family, k, seed)."""
    return (r.agent, r.route_id, str(r.family), r.k, r.seed)


def block_stats(episodes: Iterable[Sequence[Decision]]) -> DecisionStats:
    """Outcome counts, compliance, adherence and confusion over the decisions of ``episodes``."""
    counts = Counter({o.value: 0 for o in DecisionOutcome})
    contradicted = obeyed = reached = on_route = 0
    confusion: dict[str, Counter] = {}
    for decisions in episodes:
        for d in decisions:
            counts[d.outcome.value] += 1
            if d.outcome == DecisionOutcome.NOT_REACHED:
                continue
            reached += 1
            on_route += d.outcome == DecisionOutcome.FOLLOWED_ROUTE
            if d.contradicted:
                contradicted += 1
                obeyed += d.outcome == DecisionOutcome.FOLLOWED_TEXT
            confusion.setdefault(d.text_intent.value, Counter())[d.executed.value] += 1
    return DecisionStats(
        decisions={o.value: counts[o.value] for o in DecisionOutcome},
        adherence=round(on_route / reached, 4) if reached else None,
        confusion={t: dict(sorted(c.items())) for t, c in sorted(confusion.items())},
        compliance=round(obeyed / contradicted, 4) if contradicted else None,
    )


def flips(records: Sequence[EpisodeRecord], decisions: Mapping[Key, Sequence[Decision]]) -> list[dict]:
    """One row per flip (a failed variant episode whose baseline completed), sorted by key."""
    done = {(r.agent, r.route_id, r.seed) for r in records
            if r.family == Family.BASELINE and r.status == "done" and r.termination_class == "done"}
    rows = []
    for r in sorted(records, key=episode_key):
        if r.family == Family.BASELINE or r.status != "done" or r.termination_class == "done":
            continue
        if (r.agent, r.route_id, r.seed) not in done or episode_key(r) not in decisions:
            continue
        d = divergence(decisions[episode_key(r)])
        rows.append({
            "agent": r.agent, "route_id": r.route_id, "family": str(r.family), "k": r.k, "seed": r.seed,
            "termination": str(r.termination),
            "decision": None if d is None else {
                "index": d.index, "kind": d.kind, "pos": d.pos, "route_intent": d.route_intent.value,
                "outcome": d.outcome.value, "executed": None if d.executed is None else d.executed.value},
            "instruction": None if d is None else {
                "id": d.instruction_id, "text": d.text, "template": d.template,
                "intent": d.text_intent.value},
        })
    return rows


def template_ranking(flip_rows: Sequence[dict], decisions: Mapping[Key, Sequence[Decision]]) -> list[dict]:
    """Templates (and noise operations) of the variant families ranked by the flips they were
    active at: rows of family, template, flips, uses (variant episodes in which the template was
    active at a reached decision), flip_rate (flips / uses) and an example text."""
    uses: Counter = Counter()
    example: dict[tuple[str, str], str] = {}
    for key, ds in decisions.items():
        if key[2] == Family.BASELINE:
            continue
        for fam_tpl in {(key[2], d.template) for d in ds if d.outcome != DecisionOutcome.NOT_REACHED}:
            uses[fam_tpl] += 1
        for d in ds:
            example.setdefault((key[2], d.template), d.text)
    flipped = Counter((row["family"], row["instruction"]["template"]) for row in flip_rows
                      if row["instruction"] is not None)
    rows = [{"family": f, "template": t, "flips": n, "uses": uses[(f, t)],
             "flip_rate": round(n / uses[(f, t)], 4) if uses[(f, t)] else None,
             "example": example.get((f, t), "")}
            for (f, t), n in flipped.items()]
    return sorted(rows, key=lambda r: (-r["flips"], -(r["flip_rate"] or 0.0), r["family"], r["template"]))


def answer_confusion(pairs: Iterable[Sequence[tuple[Any, Any]]]) -> dict[str, dict[str, int]]:
    """Instructed intent -> answered maneuver -> count over episodes' (intent, maneuver) pairs."""
    table: dict[str, Counter] = {}
    for episode in pairs:
        for intent, maneuver in episode:
            table.setdefault(str(intent), Counter())[str(maneuver)] += 1
    return {t: dict(sorted(c.items())) for t, c in sorted(table.items())}


def attribution_doc(records: Sequence[EpisodeRecord], decisions: Mapping[Key, Sequence[Decision]]) -> dict:
    """The attribution document (attribution.json): {"flips": [...], "templates": [...]}. The
    rows' decision statistics are in the summary (:func:`icrsumo.results.aggregate.summarize`, given the
    same ``decisions``)."""
    rows = flips(records, decisions)
    return {"flips": rows, "templates": template_ranking(rows, decisions)}
