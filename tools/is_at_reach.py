"""Why IS rises under a family that ends drives early: each episode of FAMILY against its paired
baseline cut at the same route position (docs/scoring.md, "Why IS rises under misleading
text").

    python tools/is_at_reach.py OUT [--family misleading]

For every agent of an ``icrsumo evaluate`` folder (Leaderboard 1.0's rules): the mean IS of the
family's episodes, of their baselines (ΔIS as the tables print it), and of the baselines counting
only the penalised infractions at or before the route position the family's episode reached
(ΔIS at equal reach), the mean reach (share of the route), and the penalised infractions per km
of route progress (the last route point passed) of both. ΔIS at equal reach near 0 says the
tables' ΔIS comes from the shorter drive, not from safer driving. Outside-route-lanes penalties
are percentages of the route, not events: they are left out of the cut IS (the "events only"
column says how much they weigh).
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

from icrsumo.core.types import EpisodeLog
from icrsumo.core.vocab import EventKind
from icrsumo.results.store import ResultStore
from icrsumo.scoring.lb1 import counted_collisions
from icrsumo.scoring.penalties import PENALTIES

COLLISIONS = {EventKind.COLLISION_PEDESTRIAN, EventKind.COLLISION_VEHICLE, EventKind.COLLISION_STATIC}


def penalised(log: EpisodeLog) -> list[tuple[float, float]]:
    """(route position m, penalty factor) of every infraction Leaderboard 1.0 charges as an
    event: the collisions CollisionTest counts, red lights and stop signs."""
    out = [(e.pos, PENALTIES[e.kind]) for e in counted_collisions(log)]
    return out + [(e.pos, PENALTIES[e.kind]) for e in log.events
                  if e.kind in PENALTIES and e.kind not in COLLISIONS]


def is_up_to(events: list[tuple[float, float]], reach: float = float("inf")) -> float:
    """The product of the factors of the events at or before ``reach`` (m)."""
    p = 1.0
    for pos, factor in events:
        if pos <= reach + 1e-9:
            p *= factor
    return p


def analyse(out: Path, family: str) -> list[dict]:
    """One dict per agent with a baseline and ``family`` episodes in ``out``."""
    rows = []
    with ResultStore(out / "results.sqlite") as store:
        recs = [r for r in store.records() if r.status == "done"]
        base = {(r.agent, r.route_id): r for r in recs if r.family == "baseline"}
        for agent in sorted({r.agent for r in recs}):
            pairs, cache = [], {}
            for r in (r for r in recs if r.agent == agent and r.family == family):
                b = base.get((agent, r.route_id))
                if b is None:
                    continue
                if r.route_id not in cache:
                    blog = store.episode_log(agent, r.route_id, "baseline", b.k, b.seed)
                    cache[r.route_id] = penalised(blog), max(blog.progress, default=0.0) / 1000.0
                log = store.episode_log(agent, r.route_id, family, r.k, r.seed)
                reach = max(log.progress, default=0.0)
                mine = penalised(log)
                base_events, base_km = cache[r.route_id]
                pairs.append({"is": r.is_, "events_is": is_up_to(mine), "base_is": b.is_,
                              "cut_is": is_up_to(base_events, reach), "share": reach / log.route_length,
                              "km": reach / 1000.0, "n": len(mine), "base_km": base_km,
                              "base_n": len(base_events)})
            if not pairs:
                continue
            mean = {k: statistics.mean(p[k] for p in pairs) for k in pairs[0]}
            km, base_km = sum(p["km"] for p in pairs), sum(p["base_km"] for p in pairs)
            rows.append({"agent": agent, "pairs": len(pairs), **mean,
                         "per_km": sum(p["n"] for p in pairs) / km if km else None,
                         "base_per_km": sum(p["base_n"] for p in pairs) / base_km if base_km else None})
    return rows


def _f(x: float | None, fmt: str) -> str:
    return "—" if x is None else format(x, fmt).replace("-", "−")


def markdown(rows: list[dict], family: str) -> str:
    lines = [f"| agent | pairs | IS {family} (events only) | IS baseline | ΔIS "
             f"| IS baseline at the same reach | ΔIS at equal reach | reach (share of route) "
             f"| infractions per km: baseline → {family} |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| `{r['agent']}` | {r['pairs']} | {r['is']:.3f} ({r['events_is']:.3f}) | "
                     f"{r['base_is']:.3f} | {_f(r['is'] - r['base_is'], '+.3f')} | {r['cut_is']:.3f} | "
                     f"{_f(r['is'] - r['cut_is'], '+.3f')} | "
                     f"{r['share']:.2f} | {_f(r['base_per_km'], '.2f')} → {_f(r['per_km'], '.2f')} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("out", type=Path, help="an icrsumo evaluate folder")
    p.add_argument("--family", default="misleading",
                   help="the family to pair with the baseline (default misleading)")
    args = p.parse_args(argv)
    if not (args.out / "results.sqlite").is_file():
        p.error(f"{args.out}: no results.sqlite (fix: an icrsumo evaluate folder)")
    print(markdown(analyse(args.out, args.family), args.family), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
