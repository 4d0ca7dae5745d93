"""Planning: the out folder's configuration, the suite prepared into it (convert + generate),
and the episode jobs of the paired protocol in their fixed order."""

from __future__ import annotations

import re
import sys
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

from icrsumo.agents.base import Agent
from icrsumo.core.defaults import LOOP_VERSION
from icrsumo.core.errors import Field, InputError, check_seed, expect
from icrsumo.core.fsio import OutFolder, dumps_json, read_json, write_atomic
from icrsumo.core.resources import bundled_suites, suite_coords
from icrsumo.core.vocab import CONTROL_FAMILIES, DELIVERY_FAMILIES, variants_of
from icrsumo.guards.base import guarded_name
from icrsumo.instructions.baseline_bank import BaselineBank, load_baseline_bank
from icrsumo.instructions.families import FAMILIES
from icrsumo.instructions.generate import GenerateOptions, generate
from icrsumo.instructions.store import skipped_families
from icrsumo.world.convert import CONVERTER_VERSION, ConvertOptions, convert_routes, safe_name
from icrsumo.world.routes import check_route_selection, route_ids, suite_file
from icrsumo.world.scenario import find_scenarios, read_scenario

from .options import EvalOptions

#: a skipped route's line, or its InputError
Reason = TypeVar("Reason", str, InputError)


@dataclass(frozen=True)
class Job:
    """One episode to run: its store key, the files it needs, and how the worker gets the agent:
    ``agent_spec`` resolved in the worker (its learned agents on ``device``, None: cpu), or
    ``factory``, a picklable agent factory that replaces the spec (batched inference)."""

    agent_spec: str
    agent: str
    route_id: str
    family: str
    k: int
    seed: int
    scenario: str
    instructions: str
    device: str | None = None
    factory: Callable[[], Agent] | None = field(default=None, compare=False)
    #: the scoring rules (:data:`icrsumo.scoring.SCORINGS`) of the stored record
    scoring: str = "lb1"
    #: the instruction guard's spec ("" for none) and, where the workers cannot build it from
    #: the spec (an LLM guard bound to the out folder), its factory
    guard: str = ""
    guard_factory: Callable[[], object] | None = field(default=None, compare=False)
    #: the navigator answers the agent's asks (:mod:`icrsumo.sim.asking`)
    asking: bool = False
    #: what an instruction the guard blocks leaves the agent (:data:`icrsumo.guards.base.BLOCK_POLICIES`)
    on_block: str = "keep"
    #: the worker times the job's phases (``EvalOptions.profile``; the episode is the same)
    profile: bool = field(default=False, compare=False)
    #: the route's length (m): how long the episode may take (:func:`longest_first`)
    route_length: float = field(default=0.0, compare=False)

    @property
    def key(self) -> tuple[str, str, str, int, int]:
        return (self.agent, self.route_id, self.family, self.k, self.seed)


@dataclass(frozen=True)
class PreparedSuite:
    """A suite ready to run in an out folder: ``scenarios`` (the folder of converted
    scenarios), ``instructions`` (OUT/instructions), the route ids with instructions
    (``routes``) and the lines of what was skipped."""

    scenarios: Path
    instructions: Path
    routes: tuple[str, ...]
    skipped: tuple[str, ...] = ()


def folder_run(out: Path, old: Mapping) -> str:
    """The command that made an out folder (``evaluate`` or ``attack``: its episodes and files
    are that command's, so another command cannot resume or grow it), from its stored
    configuration ``old`` (``run``); for a folder written before config.json named it: attack
    where the attack's files are, else evaluate."""
    run = old.get("run")
    if isinstance(run, str):
        return run
    return "attack" if (out / "attack.json").is_file() or (out / "attack").is_dir() else "evaluate"


def check_run(out: Path, old: Mapping, run: Mapping[str, object]) -> None:
    """An InputError when the folder's stored configuration ``old`` was made by another command
    than ``run["run"]``, or with other values of the settings ``run`` names (an attack's
    ``constraint``; settings a folder written before they were recorded lacks are not
    compared)."""
    was, now = folder_run(out, old), run["run"]
    if was != now:
        raise InputError(out / "config.json", "run", f"the folder holds the results of an {was} run, "
                         f"which an {now} run cannot resume or add to (their episodes and files differ)",
                         f"give the {now} run another out folder")
    diff = [k for k in run if k != "run" and k in old and old[k] != run[k]]
    if diff:
        shown = ", ".join(f"{k}={old[k]!r} (now {run[k]!r})" for k in diff)
        raise InputError(out / "config.json", diff[0], f"the folder holds the results of an {was} run "
                         f"with other settings: {shown}",
                         f"use the same settings to resume it, or give this {now} run another out folder")


def check_config(out: Path, opts: EvalOptions, bank: BaselineBank | None = None,
                 run: Mapping[str, object] | None = None) -> dict:
    """The configuration stored in OUT/config.json; an InputError when OUT holds another one.
    ``run``: the command making the folder and its own settings that must match (default
    ``{"run": "evaluate"}``; an attack's: ``{"run": "attack", "constraint": ...}``), stored with
    it: a folder of one command is refused to the other (:func:`check_run`).
    A larger ``--k`` than the folder's is the same configuration grown: ``k_grown_from`` lists
    the folder's earlier K, and the instructions keep every earlier variant (the new ones are
    drawn from the templates those did not use).
    With a ``--baseline-bank`` (``bank``: the file already loaded) the file's SHA-256 is part of
    it (its name is recorded too, but another path to the same bytes is the same
    configuration). With ``asking`` on, ``"asking": true`` is part of it (a folder without the
    key was run without asking); so is a block policy other than keep (``"on_block"``), and the
    version of the closed loop's rules (``"loop"``, :data:`~icrsumo.core.defaults.LOOP_VERSION`;
    a folder without the key holds version 1's)."""
    run = dict(run or {"run": "evaluate"})
    config = {**run, "suite": opts.suite, "seed": opts.seed, "k": opts.k, "traffic": opts.traffic,
              "scoring": opts.scoring, "converter": CONVERTER_VERSION, "loop": LOOP_VERSION}
    if opts.asking:
        config["asking"] = True
    if opts.on_block != "keep":
        config["on_block"] = opts.on_block
    if opts.baseline_bank is not None and bank is None:
        bank = load_baseline_bank(opts.baseline_bank)
    compared = {k: v for k, v in config.items() if k not in run}
    compared["baseline_bank_sha256"] = bank.sha256 if bank is not None else None
    compared["asking"] = opts.asking
    compared["on_block"] = opts.on_block
    path = out / "config.json"
    if path.is_file():
        restore = f"restore it, or use another {Field('out')} folder"
        old = read_json(path, "evaluation configuration", restore)
        if not isinstance(old, dict):
            raise InputError(path, "", "is not a JSON object", restore)
        check_run(out, old, run)
        # a folder without the keys ran without asking, and kept what was shown before a block
        # ... and one without "loop" was run by the loop's first rules (LOOP_VERSION)
        stored = {**old, "asking": old.get("asking") is True, "on_block": old.get("on_block", "keep"),
                  "loop": old.get("loop", 1)}
        diff = [k for k in compared if stored.get(k) != compared[k]]
        history = old.get("k_grown_from")
        grown = [x for x in history if isinstance(x, int)] if isinstance(history, list) else []
        if diff == ["k"] and isinstance(old.get("k"), int) and opts.k > old["k"]:
            grown, diff = [*grown, old["k"]], []  # a larger --k adds the missing variants
        if grown:
            config["k_grown_from"] = grown
        if diff:
            shown = ", ".join(f"{k}={stored.get(k)!r} (now {compared[k]!r})" for k in diff)
            fix = f"use another {Field('out')} folder, or the same options"
            if diff == ["k"]:
                k = Field("k")
                fix = (f"use {k} {old.get('k')} or more (a larger {k} adds the missing variants), or "
                       f"another {Field('out')} folder")
            if "asking" in diff:
                fix = (f"use another {Field('out')} folder, or the same options "
                       f"({'with' if stored['asking'] else 'without'} {Field('asking')})")
            if "on_block" in diff:
                fix = (f"use another {Field('out')} folder, or the same options "
                       f"({Field('on_block')} {stored['on_block']})")
            if "converter" in diff:
                fix = ("its scenarios were converted by an earlier icrsumo, whose background traffic "
                       "differs (docs/fidelity.md, class F), so new episodes would not be comparable: "
                       f"run again into another {Field('out')} folder")
            elif "loop" in diff:
                fix = ("its episodes were recorded by the closed loop's earlier rules (docs/scoring.md, "
                       "loop versions), so new episodes would not be comparable: run again into "
                       f"another {Field('out')} folder")
            elif "scoring" in diff and old.get("scoring") is None:
                fix = ("its episodes were scored before icrsumo scored by the leaderboard's own rules: "
                       f"run them again into another {Field('out')} folder")
            elif diff == ["scoring"]:
                fix = (f"use another {Field('out')} folder, or {Field('scoring')} {old.get('scoring')}; "
                       f"icrsumo report OUT --scoring {opts.scoring} rescores the stored episodes")
            raise InputError(out, "config.json", f"holds results of a different configuration: {shown}", fix)
        if isinstance(old.get("agents"), dict):
            config["agents"] = dict(old["agents"])
    if bank is not None:
        config.update(baseline_bank_sha256=bank.sha256, baseline_bank_file=str(bank.path))
    return config


def read_config(out: Path) -> dict:
    """The checked configuration (OUT/config.json) of an evaluation folder that has a store; an
    InputError when ``out`` is not one."""
    out = Path(out)
    cfg_path = out / "config.json"
    for need in (cfg_path, out / "results.sqlite"):
        if not need.is_file():
            why = "is a folder, not a file" if need.is_dir() else "is missing" if not need.exists() \
                else "cannot be read (a broken link?)"
            raise InputError(need, "", f"{why}: {out} is not an evaluation folder",
                             f"pass the {Field('out')} folder of icrsumo evaluate")
    cfg = read_json(cfg_path, "evaluation configuration", "restore it from a copy")
    fix = "restore it from a copy"
    expect(cfg, dict, cfg_path, "", "the configuration", fix)
    for key, kind in (("suite", str), ("k", int), ("seed", int)):
        expect(cfg.get(key), kind, cfg_path, key, key, fix)
    if not 1 <= cfg["k"] <= 64:
        raise InputError(cfg_path, "k", f"{cfg['k']} is out of range (1 to 64)", fix)
    check_seed(cfg["seed"], f"{cfg_path}: seed")
    return cfg


def _resolve_suite(opts: EvalOptions, out: Path) -> tuple[Path, list[InputError]]:
    """The folder of converted scenarios for ``opts.suite`` (converting into OUT/scenarios) and
    the errors of the routes that failed."""
    p = Path(opts.suite)
    if p.is_dir() and (p / "index.json").is_file():
        return p, []
    routes = bundled_suites().get(opts.suite, p)
    target = out / "scenarios"
    coords = suite_coords(opts.suite) or "sumo"  # a bundled suite knows its frame (langauto-*: carla)
    # a first run whose routes all fail names the first route's reason (a 300-character id, two
    # ids that map to one folder), not the empty folder it would leave
    report = convert_routes(routes, target, ConvertOptions(coords=coords, traffic=opts.traffic,
                                                           workers=opts.workers),
                            refuse_empty=not (out / "results.sqlite").exists())
    return target, list(report.errors)


def _check_selection(opts: EvalOptions) -> None:
    """``routes`` and ``rollout_route`` checked against the suite's route file before anything
    is converted: a mistyped id fails at once, not after the whole suite has been converted."""
    path = suite_file(opts.suite, folders=True)
    if path is None or not (opts.routes or opts.rollout_route):
        return
    ids = route_ids(path)
    check_route_selection(opts.routes or (), ids, Field("routes"), opts.suite)
    if opts.rollout_route is not None:
        check_route_selection([opts.rollout_route], opts.routes or ids, Field("rollout_route"), opts.suite)


def prepare_suite(opts: EvalOptions, agents: Mapping[str, dict] | None = None,
                  run: Mapping[str, object] | None = None) -> PreparedSuite:
    """Check the out folder's configuration, convert the suite into OUT/scenarios (a
    convert-routes folder is used as it is), generate the instructions of every family into
    OUT/instructions (both reused when present), check ``--routes`` and ``--rollout-route``
    against the suite, and only then write OUT/config.json (with ``agents``, name -> its
    fingerprint and spec, merged into the agents it names already). Skipped routes are returned
    (``skipped``: one line each) for the caller to name.
    When anything is refused, an out folder this call created is removed again: a refused run
    leaves nothing behind (and never a config.json that locks the folder)."""
    out = Path(opts.out)
    bank = load_baseline_bank(opts.baseline_bank) if opts.baseline_bank is not None else None
    config = check_config(out, opts, bank, run)
    if agents:
        config["agents"] = {**config.get("agents", {}), **agents}
    _check_selection(opts)
    before = OutFolder.before(out)
    try:
        scenarios, skipped = _resolve_suite(opts, out)
        instr_dir = out / "instructions"
        if bank is not None and bank.note():
            print(bank.note(), file=sys.stderr)
        written, failures = generate(scenarios, instr_dir, GenerateOptions(
            families=FAMILIES + tuple(f for f in CONTROL_FAMILIES + DELIVERY_FAMILIES if f in opts.families),
            k=opts.k,
            seed=opts.seed, workers=1, baseline_bank=bank, grown_from=tuple(config.get("k_grown_from", ()))))
        if not written and not (out / "results.sqlite").exists():  # (with a store: run checks it)
            errors = list(skipped) + list(failures)
            raise errors[0] if errors else no_routes(opts)
        for rid in opts.routes or ():  # a selected route that was skipped: its own reason
            why = skip_reason((*skipped, *failures), rid) if rid not in written else None
            if why is not None:
                raise why
        check_route_ids(opts, written)
        out.mkdir(parents=True, exist_ok=True)
        write_atomic(out / "config.json", dumps_json(config))
    except BaseException:
        before.undo()
        raise
    return PreparedSuite(scenarios, instr_dir, tuple(written),
                         tuple(err.line() for err in (*skipped, *failures)))


def skip_reason(lines: Iterable[Reason], route_id: str) -> Reason | None:
    """The first of the skipped-route ``lines`` (or their InputErrors) that names ``route_id``
    (as a word or a path part), if any."""
    named = re.compile(rf"(^|[/ ']){re.escape(route_id)}([/ ':,]|$)")
    return next((line for line in lines if named.search(str(line))), None)


def no_routes(opts: EvalOptions) -> InputError:
    """The error of a suite none of whose routes could be prepared."""
    return InputError(opts.suite, "", "no route of the suite could be prepared (see the lines above)",
                      "fix the routes named above")


def check_route_ids(opts: EvalOptions, routes: Iterable[str]) -> None:
    """InputErrors for ``--routes`` or ``--rollout-route`` ids that are not among ``routes``
    (the prepared suite's)."""
    have = list(routes)
    shown = ", ".join(have[:8]) + (", ..." if len(have) > 8 else "")
    missing = sorted(set(opts.routes or ()) - set(have))
    if missing:
        raise InputError(Field("routes"), missing[0], "no such route in the suite",
                         f"use route ids of the suite: {shown}")
    chosen = set(opts.routes or have)
    if opts.rollout_route is not None and opts.rollout_route not in chosen:
        raise InputError(Field("rollout_route"), opts.rollout_route, "not a route of this evaluation",
                         f"use one of {shown}" if not opts.routes else f"use one of the {Field('routes')}")


def plan_jobs(opts: EvalOptions, scenarios: Path, instr_dir: Path, names: Mapping[str, str],
              guard_names: Mapping[str, str] | None = None) -> list[Job]:
    """Every episode of the protocol, in a fixed order (agent, guard, route, family, k);
    ``names``: agent spec -> the name its results are stored under; ``guard_names``: guard spec
    -> its name (each agent runs unguarded, then behind each of ``opts.guards``). A delivery
    family that could not be built for a route (the instructions' index names it) has no
    episodes there."""
    scs = []
    for d in find_scenarios(scenarios):
        try:
            scs.append((d, read_scenario(d)))
        except InputError:  # named as skipped when the suite was prepared
            continue
    if opts.routes:
        check_route_ids(opts, [sc.route_id for _, sc in scs])
        scs = [(d, sc) for d, sc in scs if sc.route_id in set(opts.routes)]
    sets = [("baseline", 0)] + [(f, k) for f in opts.families for k in range(variants_of(f, opts.k))]
    guard_names = guard_names or {}
    skipped = skipped_families(instr_dir)
    jobs = []
    for spec in opts.agents:
        for guard in ("", *opts.guards):
            name = guarded_name(names[spec], guard_names.get(guard, guard), opts.on_block) if guard \
                else names[spec]
            for d, sc in scs:
                instr = str(instr_dir / f"{safe_name(sc.route_id)}.json")
                for fam, k in sets:
                    if fam in skipped.get(sc.route_id, {}):
                        continue
                    jobs.append(Job(spec, name, sc.route_id, fam, k, opts.seed, str(d), instr,
                                    device=opts.agent_device, scoring=opts.scoring, guard=guard,
                                    asking=opts.asking, on_block=opts.on_block if guard else "keep",
                                    profile=opts.profile, route_length=sc.length))
    return jobs


def longest_first(jobs: list[Job]) -> list[Job]:
    """``jobs`` in the order the workers take them: the longest routes first (ties in the
    planned order), so that no worker is left with a long episode while the others wait idle
    at the end of a run. Each episode is the same whatever the order."""
    return sorted(jobs, key=lambda j: -j.route_length)
