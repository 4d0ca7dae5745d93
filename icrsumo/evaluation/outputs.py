"""The files an evaluation leaves from its stored episodes: summary.json, the tables, the
figures, the attribution, the guards' files and report.html (:mod:`icrsumo.results.aggregate` computes
the summary, :mod:`icrsumo.reporting` writes them)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from pathlib import Path

from icrsumo.core.errors import Field, InputError, note, note_names
from icrsumo.core.types import EpisodeLog, EpisodeRecord
from icrsumo.instructions.families import ALL_FAMILIES
from icrsumo.instructions.store import skipped_families
from icrsumo.results.store import ResultStore
from icrsumo.results.summary import Summary
from icrsumo.scoring import get_scoring
from icrsumo.world.convert import safe_name
from icrsumo.world.scenario import Scenario, find_scenarios, read_scenario

from .options import EvalOptions


def write_outputs(opts: EvalOptions, out: Path, store: ResultStore, records: list[EpisodeRecord],
                  scenarios: Path, instr_dir: Path, not_shown: int = 0, rescored_short: int = 0,
                  not_shown_why: str = "") -> Summary:
    """Write summary.json, tables and figures of ``records`` into ``out`` (the table is printed
    unless ``opts.quiet``); returns the summary, whose ``digest`` covers every episode in
    ``store`` (:mod:`icrsumo.evaluation.digests`) under ``opts.scoring``. ``rescored_short``:
    rescored episodes that ended before the report's scoring would have ended them (counted in the summary,
    ``episodes.rescored_short``, and named on stderr). ``not_shown``: episodes in the store that are
    not of this evaluation (other agents, routes, families or k), counted in the summary
    (``episodes.stored_not_in_report``, with ``not_shown_why`` or a default reason as
    ``stored_not_in_report_why``) and named on stderr, never dropped silently."""
    from icrsumo.reporting.attribution import write_attribution
    from icrsumo.reporting.rollout import rollout_figure
    from icrsumo.reporting.write import write_report
    from icrsumo.results.aggregate import summarize
    from icrsumo.results.attribution import attribution_doc

    families = tuple(f for f in ALL_FAMILIES if f in opts.families)  # canonical order
    digest = store_digest(store, opts.scoring)
    ends: dict = {}
    answers: dict = {}
    decisions = episode_decisions(store, records, instr_dir, ends, answers)
    if rescored_short:
        note(f"{rescored_short} episodes ended, under the rules they were run with, before "
             f"{opts.scoring}'s rules would have ended them: they are scored on what was simulated "
             f"(run them with {Field('scoring')} {opts.scoring} for the full episodes)")
    why = ""
    if not_shown:
        why = not_shown_why or (f"they are of other agents, routes, families or k (icrsumo report {out} "
                                f"shows all)")
        note(f"{not_shown} stored episodes are not in this report: {why}")
    try:
        skipped = skipped_families(instr_dir)
    except InputError as err:  # the counts are extra: the tables are written without them
        note(f"no skipped-route counts: {err.line(note_names())}")
        skipped = {}
    routes = {r.route_id for r in records}
    skipped_routes = Counter(f for rid, fams in skipped.items() if rid in routes for f in fams)
    summary = summarize(records, suite=opts.suite, seed=opts.seed, k=opts.k, families=families,
                        scoring=opts.scoring, digest=digest, decisions=decisions, answers=answers,
                        rescored_short=rescored_short, not_in_report=not_shown, not_in_report_why=why,
                        skipped_routes=skipped_routes)
    attribution = attribution_doc(records, decisions)
    scen = route_scenarios(scenarios)
    table = write_report(summary, records, out, ends,
                         key_points={rid: sc.key_points for rid, sc in scen.items() if sc.key_points},
                         logs=crash_logs(store))
    write_attribution(summary, attribution, out)
    table += write_guards(summary, records, out)
    write_html(out, summary, records, attribution, store, scen, instr_dir)
    try:
        rollout_figure(out, store, records, scenarios, instr_dir, route=opts.rollout_route, seed=opts.seed,
                       families=opts.families, scoring=get_scoring(opts.scoring))
    except InputError as err:  # the figure is optional; the numbers are all in the tables
        note(f"no rollout figure: {err.line(note_names())}")
    if not opts.quiet:
        print(table)
    return summary


def write_guards(summary: Summary, records: list[EpisodeRecord], out: Path) -> str:
    """guard.json, guard.md and its figure when a row of ``summary`` is guarded
    (:func:`icrsumo.results.guards.guard_doc`); returns what the printed table adds of them
    ("" without a guarded row)."""
    from icrsumo.guards.base import split_policy
    from icrsumo.reporting.guard import guard_note, write_guard
    from icrsumo.results.guards import guard_doc, text_holdout

    guards = guard_doc(summary, records)
    if guards is None:
        return ""
    if any(split_policy(r["guard"])[0] == "text" for r in guards["rows"].values()):
        from icrsumo.guards.text import TextGuard
        from icrsumo.instructions.banks import load_banks

        guards["text_holdout"] = text_holdout(TextGuard(), load_banks())
    write_guard(guards, out)
    return "\n" + guard_note(guards)


def store_digest(store: ResultStore, scoring: str) -> str | None:
    """The digest of every episode in ``store`` under ``scoring`` (:mod:`icrsumo.evaluation.digests`), or
    None, named on stderr, when the store has none (a damaged stored log: the tables are still
    written, as they are without that episode's decisions)."""
    from .digests import run_digest

    try:
        return run_digest(store, scoring)
    except InputError as err:
        note(f"no digest: {err.line(note_names())}")
        return None


def route_scenarios(scenarios: Path) -> dict[str, Scenario]:
    """Route id -> its scenario, for every scenario of the convert-routes folder ``scenarios``
    that can be read ({} when it is none): a route whose scenario cannot be read is left out,
    and what needs it does without."""
    scen = {}
    if Path(scenarios).is_dir() and (Path(scenarios) / "index.json").is_file():
        for d in find_scenarios(scenarios):
            try:
                sc = read_scenario(d)
            except InputError:
                continue
            scen[sc.route_id] = sc
    return scen


def crash_logs(store: ResultStore) -> Callable[[EpisodeRecord], EpisodeLog | None]:
    """A crashed episode's stored log (its steps up to the crash), which the leaderboard files
    score; a damaged one is named on stderr and the episode scored as stored without one."""
    def log(r: EpisodeRecord) -> EpisodeLog | None:
        try:
            return store.episode_log(r.agent, r.route_id, r.family, r.k, r.seed)
        except InputError as err:
            note(f"the leaderboard files score a crashed episode as having no log: {err.line()}")
            return None

    return log


def write_html(out: Path, summary: Summary, records: list[EpisodeRecord], attribution: dict,
               store: ResultStore, scen: dict[str, Scenario], instr_dir: Path) -> None:
    """OUT/report.html (:mod:`icrsumo.reporting.html`) from the stored logs, the routes'
    instruction files and networks (``scen``: :func:`route_scenarios`); a route whose files
    cannot be read is drawn without them."""
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.render import BevRenderer, map_view_png
    from icrsumo.reporting.html import write_html_report
    from icrsumo.world.networks import load_net

    loaded_nets: dict[str, object] = {}
    renderers: dict[str, BevRenderer] = {}

    def logs(r: EpisodeRecord):
        try:
            return store.episode_log(r.agent, r.route_id, r.family, r.k, r.seed)
        except InputError:
            return None

    def sets(route: str) -> dict:
        try:
            found = read_instruction_sets(instr_dir / f"{safe_name(route)}.json")
            return {(str(s.family), s.k): s for s in found}
        except InputError:
            return {}

    def nets(route: str):
        sc = scen.get(route)
        if sc is None:
            return None
        if str(sc.net) not in loaded_nets:
            try:
                loaded_nets[str(sc.net)] = load_net(sc.net)
            except InputError:
                loaded_nets[str(sc.net)] = None
        return loaded_nets[str(sc.net)]

    def render(route: str):
        net = nets(route)
        if net is None:
            return None
        key = str(scen[route].net)
        if key not in renderers:
            renderers[key] = BevRenderer(net)
        r = renderers[key]
        return lambda x, y, yaw: map_view_png(r, x, y, yaw)

    write_html_report(out / "report.html", summary, records, attribution, logs, sets, nets, render)


def episode_decisions(store: ResultStore, records: list[EpisodeRecord], instr_dir: Path,
                      ends: dict | None = None, answers: dict | None = None) -> dict:
    """Key -> the decisions (:func:`icrsumo.results.decisions.classify_decisions`) of every finished
    episode in ``records``, from its stored log and its route's instruction file; a route whose
    instruction file cannot be read, or an episode whose stored log is damaged, is left out and
    named on stderr. ``ends`` (filled when given): key -> where and when each episode ended and
    the ids of its instruction texts (:data:`icrsumo.results.aggregate.END_COLUMNS`), read on the way;
    ``answers`` (filled when given): key -> a language-model agent's (instructed intent,
    answered maneuver) pairs (:func:`icrsumo.results.decisions.answer_pairs`)."""
    from icrsumo.instructions.store import read_route_file
    from icrsumo.results.decisions import answer_pairs, classify_decisions

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
            iset = route[1][(r.family, r.k)]
            out[(r.agent, r.route_id, str(r.family), r.k, r.seed)] = classify_decisions(route[0], iset, log)
            if answers is not None and log.model_calls:
                answers[(r.agent, r.route_id, str(r.family), r.k, r.seed)] = answer_pairs(iset, log)
            if ends is not None and log.t:
                ends[(r.agent, r.route_id, r.family, r.k, r.seed)] = {
                    "instructions": "|".join(i.template or "baseline" for i in iset.instructions),
                    "end_t": round(log.t[-1], 2), "end_pos": round(log.progress[-1], 1),
                    "end_x": round(log.x[-1], 1), "end_y": round(log.y[-1], 1)}
    if unreadable:
        note(f"no decision attribution for {len(unreadable)} routes whose instruction file cannot be "
             f"read (first: {unreadable[0]})")
    if damaged:
        note(f"{len(damaged)} stored episode logs cannot be read, so their decisions are not in the "
             f"attribution (first: {damaged[0]})")
    return out
