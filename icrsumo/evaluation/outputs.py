"""The files an evaluation leaves from its stored episodes: summary.json, the tables
(:mod:`icrsumo.aggregate`, :mod:`icrsumo.report`) and the paired rollout figure."""

from __future__ import annotations

import sys
from pathlib import Path

from ..convert import safe_name
from ..errors import InputError
from ..instructions.families import FAMILIES
from ..scenario import find_scenarios, read_scenario
from ..store import ResultStore
from ..types import EpisodeRecord
from .options import EvalOptions


def write_outputs(opts: EvalOptions, out: Path, store: ResultStore, records: list[EpisodeRecord],
                  scenarios: Path, instr_dir: Path, not_shown: int = 0) -> dict:
    """Write summary.json, tables and figures of ``records`` into ``out`` (the table is printed
    unless ``opts.quiet``); returns the summary. ``not_shown``: episodes in the store that are
    not of this evaluation (other agents, routes, families or k), counted in the summary
    (``episodes.stored_not_in_report``) and named on stderr, never dropped silently."""
    from ..aggregate import summarize
    from ..report import write_report

    families = tuple(f for f in FAMILIES if f in opts.families)  # canonical order
    summary = summarize(records, suite=opts.suite, seed=opts.seed, k=opts.k, families=families)
    if not_shown:
        summary["episodes"]["stored_not_in_report"] = not_shown
        print(f"icrsumo: note: {not_shown} stored episodes of other agents, routes, families or k are "
              f"not in this report (icrsumo report {out} shows all)", file=sys.stderr)
    table = write_report(summary, records, out)
    try:
        rollout_figure(opts, out, store, records, scenarios, instr_dir)
    except InputError as err:  # the figure is optional; the numbers are all in the tables
        print(f"icrsumo: note: no rollout figure: {err.line()}", file=sys.stderr)
    if not opts.quiet:
        print(table)
    return summary


def rollout_figure(opts: EvalOptions, out: Path, store: ResultStore, records: list[EpisodeRecord],
                   scenarios: Path, instr_dir: Path) -> None:
    """Paired rollout figure: baseline vs k = 0 of each family for one route and agent
    (``opts.rollout_route``, default the first with a finished baseline)."""
    from ..instructions.store import read_instruction_sets
    from ..logs import loads_log
    from ..networks import load_net
    from ..report import paired_rollout

    done = [r for r in records if r.status == "done" and r.family == "baseline"]
    if not done:
        return
    route = opts.rollout_route or done[0].route_id
    agent = done[0].agent
    base_json = store.log(agent, route, "baseline", 0, opts.seed)
    if base_json is None:
        return
    sets = {(s.family, s.k): s for s in read_instruction_sets(instr_dir / f"{safe_name(route)}.json")}
    variants = []
    for fam in opts.families:
        lj = store.log(agent, route, fam, 0, opts.seed)
        if lj is not None and (fam, 0) in sets:
            variants.append((f"{fam} k=0", loads_log(lj), sets[(fam, 0)].instructions[0].rendered()))
    sc_dir = next((d for d in find_scenarios(scenarios) if read_scenario(d).route_id == route), None)
    if sc_dir is None:
        return
    net = load_net(read_scenario(sc_dir).net)
    fig = out / "figures" / f"rollout_{safe_name(route)}.png"
    fig.parent.mkdir(parents=True, exist_ok=True)
    paired_rollout(net, loads_log(base_json), variants, sets[("baseline", 0)].instructions[0].rendered(),
                   fig, title=f"{agent} on {route}")
