"""A small hand-made set of episode records shared by the aggregation and report tests
(2 agents x 3 routes x K=2; the hand-computed values are in tests/test_aggregate.py)."""

from __future__ import annotations

from dataclasses import replace

from icrsumo.core.types import EpisodeRecord

TERM = {"done": "completed", "RD": "route_deviation", "TO": "route_timeout"}


def rec(agent, route, family, k, ds=0.0, rc=0.0, is_=1.0, cls="done", status="done", seed=7, **kw):
    if status == "crashed":
        return EpisodeRecord(agent, route, family, k, seed, status="crashed", message="boom", attempts=2)
    return EpisodeRecord(agent, route, family, k, seed, status=status, ds=ds, rc=rc, is_=is_,
                         termination=TERM[cls], termination_class=cls, length=500.0, duration=60.0, **kw)


def tiny() -> list[EpisodeRecord]:
    """2 agents x 3 routes x K=2. A: baseline + paraphrase; B: baseline + misleading, with crashes."""
    return [
        rec("A", "r1", "baseline", 0, 80, 100, 0.8),
        rec("A", "r2", "baseline", 0, 60, 60, 1.0, "TO"),
        rec("A", "r3", "baseline", 0, 50, 100, 0.5),
        rec("A", "r1", "paraphrase", 0, 70, 100, 0.7),
        rec("A", "r1", "paraphrase", 1, 40, 50, 0.8, "RD"),
        rec("A", "r2", "paraphrase", 0, 60, 60, 1.0, "TO"),
        rec("A", "r2", "paraphrase", 1, 30, 30, 1.0, "TO"),
        rec("A", "r3", "paraphrase", 0, 50, 100, 0.5),
        rec("A", "r3", "paraphrase", 1, 50, 100, 0.5),
        rec("B", "r1", "baseline", 0, 100, 100, 1.0),
        rec("B", "r2", "baseline", 0, status="crashed"),
        rec("B", "r3", "baseline", 0, 90, 100, 0.9),
        rec("B", "r1", "misleading", 0, 20, 20, 1.0, "RD"),
        rec("B", "r1", "misleading", 1, status="crashed"),
        rec("B", "r2", "misleading", 0, 10, 10, 1.0, "RD"),
        rec("B", "r2", "misleading", 1, 50, 50, 1.0, "TO"),
        rec("B", "r3", "misleading", 0, 90, 100, 0.9),
        rec("B", "r3", "misleading", 1, 45, 50, 0.9, "RD"),
    ]


FAMS = ("paraphrase", "misleading")


#: the per-route conditioning gains (baseline − blank: DS, RC, IS) of :func:`with_blank`'s agent A
GAINS_A = ((40.0, 50.0, 0.0), (0.0, 0.0, 0.0), (30.0, 0.0, 0.3), (30.0, 60.0, 0.0))


def with_blank() -> list[EpisodeRecord]:
    """Agent A: 4 routes (seed 7) with a baseline and a blank episode each (gains
    :data:`GAINS_A`), plus a crashed blank with its baseline (r5) and a blank of seed 8, whose
    baseline is missing: both left out. Agent O ignores language: its blank equals its baseline."""
    base = [(80, 100, 0.8, "done"), (60, 60, 1.0, "TO"), (100, 100, 1.0, "done"), (50, 100, 0.5, "done")]
    out = []
    for i, ((ds, rc, is_, cls), (g_ds, g_rc, g_is)) in enumerate(zip(base, GAINS_A), start=1):
        out.append(rec("A", f"r{i}", "baseline", 0, ds, rc, is_, cls))
        out.append(rec("A", f"r{i}", "blank", 0, ds - g_ds, rc - g_rc, is_ - g_is, "RD" if g_rc else cls))
        out.append(rec("O", f"r{i}", "baseline", 0, 100, 100, 1.0))
        out.append(rec("O", f"r{i}", "blank", 0, 100, 100, 1.0))
    return out + [rec("A", "r5", "baseline", 0, 90, 100, 0.9), rec("A", "r5", "blank", 0, status="crashed"),
                  rec("A", "r1", "blank", 0, 0, 0, 1.0, "RD", seed=8)]


#: (agent, route, family, k) -> (asks, answered) of :func:`with_asks`
ASKS = {("A", "r1", "baseline", 0): (2, 1), ("A", "r1", "paraphrase", 0): (1, 1),
        ("A", "r2", "paraphrase", 1): (3, 1), ("B", "r2", "misleading", 0): (5, 5)}


def with_asks() -> list[EpisodeRecord]:
    """:func:`tiny` with asks for clarification (:data:`ASKS`) on a few episodes; B's ask is on a
    misleading episode whose baseline crashed (unpaired: left out of its row)."""
    out = []
    for r in tiny():
        asks, answered = ASKS.get((r.agent, r.route_id, r.family, r.k), (0, 0))
        out.append(replace(r, asks=asks, asks_answered=answered))
    return out
