"""A small hand-made set of episode records shared by the aggregation and report tests
(2 agents x 3 routes x K=2; the hand-computed values are in tests/test_aggregate.py)."""

from __future__ import annotations

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
