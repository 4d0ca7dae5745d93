"""What a guard catches and what it wrongly blocks, from stored episodes (pure; no SUMO).

For every guarded row ``AGENT+guard:NAME`` of an evaluation beside its unguarded ``AGENT`` row,
per family (baseline included):

- ``checked`` / ``blocked`` / ``block_rate``: the guard's decisions on the family's instructions
  (finished episodes; texts the family kept unchanged and empty texts are not counted). On
  ``misleading`` the block rate is the guard's *detection*; on the goal-preserving families
  (baseline, paraphrase, noise, and the delivery families ``timing``, ``distance`` and ``notice``
  where run; ambiguity and ``correction``, which opens with a misleading text, reported apart) it
  is its *false blocks*;
- ``guarded`` / ``unguarded``: DS, RC, IS and ΔDS (against each row's own baseline) from the
  summary, and ``dDS_shrink``: 1 - ΔDS guarded / ΔDS unguarded (None unless the unguarded ΔDS
  is negative);
- ``flips``: pairs (route, k) the guard ``prevented`` (the unguarded episode failed, the guarded
  one completed) and ``caused`` (the reverse), "completed" meaning termination class done;
- ``loss``: the paired difference DS guarded - DS unguarded (mean over pairs), its two-sided
  Wilcoxon signed-rank p-value over per-route means (zero differences dropped), Holm-corrected
  over the row's families (as the tables' p-values), and ``significant_loss`` (p < 0.05 and a
  negative mean).

A repaired instruction (the guard's own repair, or the ``navigator`` block policy's: rows
``AGENT+guard:NAME+navigator``) is blocked too: it was not shown as written. A row run under the
navigator policy, or with any repair, also has ``on_block`` and, per family, ``repairs``: how
many instructions were ``repaired`` and what that bought, from this folder alone: over the
finished ``episodes`` with a repair and the ``pairs`` of them whose unguarded episode is stored
too, the mean ``DS`` / ``RC`` guarded and ``DS_unguarded`` / ``RC_unguarded`` (None without
pairs). What repair bought over blocking is the navigator row's DS against the same guard's
under keep, which another out folder holds (the policy is part of a folder's configuration).

``guards`` pools each guard's block rates over its rows: ``detection`` (misleading) and
``false_blocks`` (the goal-preserving families run), ``false_blocks_ambiguity`` apart, and, where it
repaired, ``repaired``: the instructions repaired per family. A guard under the navigator policy
is its own entry (``plan+navigator``). A guard's targets (:data:`TARGETS`) are checked where it
has them. guard.json, guard.md and its figure are written by :mod:`icrsumo.reporting.guard`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from icrsumo.core.types import EpisodeRecord
from icrsumo.core.vocab import EpisodeStatus, Family
from icrsumo.guards.base import split_policy, split_row
from icrsumo.instructions.banks import template_number

from .aggregate import holm, paired_test
from .summary import Block, FamilyStats, Summary

GUARD_FORMAT = "icrsumo-guard/1"
#: goal-preserving families whose blocks are false blocks (ambiguity and correction are reported
#: apart: an ambiguous text has no goal to keep, a correction opens with a misleading text)
PRESERVING = (Family.BASELINE, Family.PARAPHRASE, Family.NOISE, Family.TIMING, Family.DISTANCE, Family.NOTICE)
#: the issue's targets: guard -> (detection at least, false blocks at most, misleading ΔDS shrink at least)
TARGETS = {"plan": {"detection": 0.95, "false_blocks": 0.01, "dDS_shrink": 0.80},
           "plan+navigator": {"detection": 0.95, "false_blocks": 0.01, "dDS_shrink": 0.90}}


def _rate(blocked: int, checked: int) -> float | None:
    return round(blocked / checked, 4) if checked else None


def _scores(block: Block | None) -> dict[str, Any]:
    """DS, RC, IS and ΔDS of a summary's row (None each without the row; ΔDS None on a baseline)."""
    if block is None:
        return {"DS": None, "RC": None, "IS": None, "dDS": None}
    d_ds = block.d_ds if isinstance(block, FamilyStats) else None
    return {"DS": block.ds, "RC": block.rc, "IS": block.is_, "dDS": d_ds}


def _block(summary: Summary, name: str, family: str) -> Block | None:
    """The row of agent ``name`` and ``family`` in ``summary`` (None: not there)."""
    a = summary.agents.get(name)
    if a is None:
        return None
    return a.baseline if family == Family.BASELINE else a.families.get(family)


def _pairs(records: Sequence[EpisodeRecord], agent: str, family: str) -> dict[tuple, EpisodeRecord]:
    return {(r.route_id, r.k, r.seed): r for r in records
            if r.agent == agent and r.family == family and r.status == EpisodeStatus.DONE}


def _mean(values: Sequence[float]) -> float | None:
    return round(float(np.mean(values)), 4) if len(values) else None


def _repairs(g: dict[tuple, EpisodeRecord], u: dict[tuple, EpisodeRecord]) -> dict[str, Any]:
    """What a family's repairs bought (module doc): ``g`` / ``u`` the guarded and unguarded
    finished episodes by (route, k, seed)."""
    mine = [k for k, r in g.items() if r.guard_repaired]
    both = [k for k in mine if k in u]
    return {"repaired": sum(g[k].guard_repaired for k in mine), "episodes": len(mine), "pairs": len(both),
            "DS": _mean([g[k].ds for k in both]), "DS_unguarded": _mean([u[k].ds for k in both]),
            "RC": _mean([g[k].rc for k in both]), "RC_unguarded": _mean([u[k].rc for k in both])}


def _row(summary: Summary, records: Sequence[EpisodeRecord], row: str, base: str,
         repairs: bool = False) -> dict[str, Any]:
    """Per family of guarded row ``row`` against ``base`` (module doc); ``repairs``: with what
    repairs bought."""
    fams = [str(Family.BASELINE), *summary.families]
    out: dict[str, Any] = {}
    raw_p: list[float | None] = []
    for fam in fams:
        g, u = _pairs(records, row, fam), _pairs(records, base, fam)
        checked = sum(r.guard_checked for r in g.values())
        blocked = sum(r.guard_blocked for r in g.values())
        both = sorted(set(g) & set(u))
        prevented = sum(u[k].termination_class != "done" and g[k].termination_class == "done" for k in both)
        caused = sum(u[k].termination_class == "done" and g[k].termination_class != "done" for k in both)
        per_route: dict[tuple, list[float]] = {}
        for k in both:
            per_route.setdefault((k[0], k[2]), []).append(g[k].ds - u[k].ds)
        means = np.array([np.mean(v) for v in per_route.values()], dtype=float)
        p = round(paired_test(means), 6) if len(means) else None
        raw_p.append(p)
        gs, us = _scores(_block(summary, row, fam)), _scores(_block(summary, base, fam))
        shrink = None
        if fam != Family.BASELINE and us["dDS"] is not None and gs["dDS"] is not None and us["dDS"] < 0:
            shrink = round(1.0 - gs["dDS"] / us["dDS"], 4)
        diff = round(float(np.mean([g[k].ds - u[k].ds for k in both])), 4) if both else None
        out[fam] = {"checked": checked, "blocked": blocked, "block_rate": _rate(blocked, checked),
                    "guarded": gs, "unguarded": us, "dDS_shrink": shrink, "pairs": len(both),
                    "flips": {"prevented": prevented, "caused": caused},
                    "loss": {"mean_dDS_vs_unguarded": diff, "p_value_raw": p},
                    **({"repairs": _repairs(g, u)} if repairs else {})}
    for fam, p in zip(fams, holm(raw_p)):
        loss = out[fam]["loss"]
        loss["p_value"] = None if p is None else round(p, 6)
        worse = (loss["mean_dDS_vs_unguarded"] or 0.0) < 0
        loss["significant_loss"] = bool(p is not None and p < 0.05 and worse)
    return out


def guard_doc(summary: Summary, records: Sequence[EpisodeRecord]) -> dict[str, Any] | None:
    """The guard document (module doc) of an evaluation's ``summary`` and ``records``; None
    when no row is guarded."""
    rows: dict[str, dict] = {}
    pooled: dict[str, dict[str, list[int]]] = {}
    for name in summary.agents:
        parts = split_row(name)
        if parts is None:
            continue
        agent, guard = parts
        policy = split_policy(guard)[1]
        repairs = policy != "keep" or any(r.guard_repaired for r in records if r.agent == name)
        fams = _row(summary, records, name, agent, repairs)
        rows[name] = {"agent": agent, "guard": guard, "unguarded_in_run": agent in summary.agents,
                      **({"on_block": policy} if repairs else {}), "families": fams}
        acc = pooled.setdefault(guard, {})
        for fam, f in fams.items():
            c = acc.setdefault(fam, [0, 0, 0])
            c[0] += f["checked"]
            c[1] += f["blocked"]
            c[2] += f["repairs"]["repaired"] if repairs else 0
    if not rows:
        return None
    guards = {}
    for guard, acc in pooled.items():
        def rate(fams: Sequence[str], acc: dict = acc) -> float | None:
            checked = sum(acc.get(str(f), [0, 0])[0] for f in fams)
            return _rate(sum(acc.get(str(f), [0, 0])[1] for f in fams), checked)
        entry: dict[str, Any] = {
            "detection": rate([Family.MISLEADING]), "false_blocks": rate(PRESERVING),
            "false_blocks_ambiguity": rate([Family.AMBIGUITY]),
            "block_rate": {fam: _rate(c[1], c[0]) for fam, c in acc.items()}}
        if any(r.get("on_block") for r in rows.values() if r["guard"] == guard):
            entry["repaired"] = {fam: c[2] for fam, c in acc.items()}
        target = TARGETS.get(guard)
        if target is not None:
            shrinks = [r["families"].get(Family.MISLEADING, {}).get("dDS_shrink") for r in rows.values()
                       if r["guard"] == guard]
            entry["targets"] = {
                "detection": {"target": target["detection"], "value": entry["detection"],
                              "met": entry["detection"] is not None
                              and entry["detection"] >= target["detection"]},
                "false_blocks": {"target": target["false_blocks"], "value": entry["false_blocks"],
                                 "met": entry["false_blocks"] is not None
                                 and entry["false_blocks"] <= target["false_blocks"]},
                "dDS_shrink": {"target": target["dDS_shrink"], "values": shrinks,
                               "met": bool(shrinks) and all(s is not None and s >= target["dDS_shrink"]
                                                            for s in shrinks)},
                "no_significant_loss": {"met": not any(
                    r["families"].get(f, {}).get("loss", {}).get("significant_loss")
                    for r in rows.values() if r["guard"] == guard for f in PRESERVING)}}
        guards[guard] = entry
    return {"format": GUARD_FORMAT, "guards": guards, "rows": rows}


def text_holdout(guard, banks) -> dict[str, Any]:
    """Detection of a text-only ``guard`` on the misleading bank's templates, split into the
    half its cues were written from (odd template numbers) and the held-out half (even), and
    its block rate on the paraphrase bank (false blocks), each template filled once as the
    generator fills it (``{junction}`` -> "the next junction", ``[x]`` -> 100 m) and checked with
    no previous instruction. ``banks``: :class:`icrsumo.instructions.banks.Banks`."""
    from icrsumo.guards.base import GuardContext, verdict_of
    from icrsumo.instructions.banks import fill

    ctx = GuardContext(t=0.0, progress=0.0, instruction_id=0, previous="")

    def blocked(text: str) -> bool:
        verdict, _ = verdict_of(guard.check(fill(text, "crossroad").replace("[x]", "100"), ctx), "text")
        return str(verdict) == "block"

    halves: dict[str, list[bool]] = {"tuning": [], "held_out": []}
    for by_kind in banks.misleading.values():
        for entries in by_kind.values():
            for e in entries:
                n = template_number(e.id)
                halves["tuning" if n is not None and n % 2 else "held_out"].append(blocked(e.text))
    para = [blocked(e.text) for by_kind in banks.paraphrase.values() for entries in by_kind.values()
            for e in entries]
    return {"split": "tuning: odd template numbers (M.*.p01, p03, ... d15); held out: even",
            **{k: {"templates": len(v), "detected": sum(v), "detection": _rate(sum(v), len(v))}
               for k, v in halves.items()},
            "paraphrase_bank": {"templates": len(para), "blocked": sum(para),
                                "block_rate": _rate(sum(para), len(para))}}
