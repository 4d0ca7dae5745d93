"""The files an evaluation leaves from its stored episodes: summary.json, the tables
(:mod:`icrsumo.aggregate`, :mod:`icrsumo.report`) and the paired rollout figure."""

from __future__ import annotations

import sys
from pathlib import Path

from ..convert import safe_name
from ..errors import InputError
from ..instructions.families import ALL_FAMILIES
from ..scenario import find_scenarios, read_scenario
from ..store import ResultStore
from ..types import EpisodeRecord
from .options import EvalOptions


def write_outputs(opts: EvalOptions, out: Path, store: ResultStore, records: list[EpisodeRecord],
                  scenarios: Path, instr_dir: Path, not_shown: int = 0, rescored_short: int = 0) -> dict:
    """Write summary.json, tables and figures of ``records`` into ``out`` (the table is printed
    unless ``opts.quiet``); returns the summary. ``rescored_short``: rescored episodes that
    ended before the report's scoring would have ended them (counted in the summary,
    ``episodes.rescored_short``, and named on stderr). ``not_shown``: episodes in the store that are
    not of this evaluation (other agents, routes, families or k), counted in the summary
    (``episodes.stored_not_in_report``) and named on stderr, never dropped silently."""
    from ..aggregate import summarize
    from ..attribution import attach
    from ..report import write_attribution, write_report

    families = tuple(f for f in ALL_FAMILIES if f in opts.families)  # canonical order
    summary = summarize(records, suite=opts.suite, seed=opts.seed, k=opts.k, families=families)
    summary["scoring"] = opts.scoring
    attribution = attach(summary, records, episode_decisions(store, records, instr_dir))
    if rescored_short:
        summary["episodes"]["rescored_short"] = rescored_short
        print(f"icrsumo: note: {rescored_short} episodes ended, under the rules they were run with, "
              f"before {opts.scoring}'s rules would have ended them: they are scored on what was simulated "
              f"(run them with --scoring {opts.scoring} for the full episodes)", file=sys.stderr)
    if not_shown:
        summary["episodes"]["stored_not_in_report"] = not_shown
        print(f"icrsumo: note: {not_shown} stored episodes of other agents, routes, families or k are "
              f"not in this report (icrsumo report {out} shows all)", file=sys.stderr)
    table = write_report(summary, records, out)
    write_attribution(summary, attribution, out)
    try:
        rollout_figure(opts, out, store, records, scenarios, instr_dir)
    except InputError as err:  # the figure is optional; the numbers are all in the tables
        print(f"icrsumo: note: no rollout figure: {err.line()}", file=sys.stderr)
    if not opts.quiet:
        print(table)
    return summary


def episode_decisions(store: ResultStore, records: list[EpisodeRecord], instr_dir: Path) -> dict:
    """Key -> the decisions (:func:`icrsumo.decisions.classify_decisions`) of every finished
    episode in ``records``, from its stored log and its route's instruction file; a route whose
    instruction file cannot be read, or an episode whose stored log is damaged, is left out and
    named on stderr."""
    from ..decisions import classify_decisions
    from ..instructions.store import read_route_file

    routes: dict[str, tuple | None] = {}
    out = {}
    damaged: list[str] = []
    unreadable: list[str] = []
    for r in records:
        if r.status != "done":
            continue
        if r.route_id not in routes:
            path = instr_dir / f"{safe_name(r.route_id)}.json"
            try:
                sets, maneuvers = read_route_file(path)
                routes[r.route_id] = (maneuvers, {(s.family, s.k): s for s in sets})
            except InputError as err:
                routes[r.route_id] = None
                unreadable.append(err.line())
        route = routes[r.route_id]
        if route is None or (r.family, r.k) not in route[1]:
            continue
        try:
            log = store.episode_log(r.agent, r.route_id, r.family, r.k, r.seed)
        except InputError as err:  # the numbers are in the tables; only its decisions are missing
            damaged.append(err.line())
            continue
        if log is not None:
            out[(r.agent, r.route_id, str(r.family), r.k, r.seed)] = classify_decisions(
                route[0], route[1][(r.family, r.k)], log)
    if unreadable:
        print(f"icrsumo: note: no decision attribution for {len(unreadable)} routes whose instruction file "
              f"cannot be read (first: {unreadable[0]})", file=sys.stderr)
    if damaged:
        print(f"icrsumo: note: {len(damaged)} stored episode logs cannot be read, so their decisions are "
              f"not in the attribution (first: {damaged[0]})", file=sys.stderr)
    return out


def rollout_figure(opts: EvalOptions, out: Path, store: ResultStore, records: list[EpisodeRecord],
                   scenarios: Path, instr_dir: Path) -> None:
    """Paired rollout figure: baseline vs k = 0 of each family for one route and agent
    (``opts.rollout_route``, default the first with a finished baseline)."""
    from ..instructions.store import read_instruction_sets
    from ..networks import load_net
    from ..report import paired_rollout

    done = [r for r in records if r.status == "done" and r.family == "baseline"]
    if not done:
        return
    route = opts.rollout_route or done[0].route_id
    agent = done[0].agent
    base_log = store.episode_log(agent, route, "baseline", 0, opts.seed)
    if base_log is None:
        return
    sets = {(s.family, s.k): s for s in read_instruction_sets(instr_dir / f"{safe_name(route)}.json")}
    variants = []
    for fam in opts.families:
        log = store.episode_log(agent, route, fam, 0, opts.seed)
        if log is not None and (fam, 0) in sets:
            variants.append((f"{fam} k=0", log, sets[(fam, 0)].instructions[0].rendered()))
    sc_dir = next((d for d in find_scenarios(scenarios) if read_scenario(d).route_id == route), None)
    if sc_dir is None:
        return
    net = load_net(read_scenario(sc_dir).net)
    fig = out / "figures" / f"rollout_{safe_name(route)}.png"
    fig.parent.mkdir(parents=True, exist_ok=True)
    paired_rollout(net, base_log, variants, sets[("baseline", 0)].instructions[0].rendered(),
                   fig, title=f"{agent} on {route}")
