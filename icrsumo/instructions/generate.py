"""``icrsumo generate``: baseline sequence + K variants per family for every converted route.

Randomness: phrasings of the baseline come from a Generator seeded with the route's seed (from
the scenario); every counterfactual draw of a route comes from one Generator seeded with
``(--seed, crc32(route id))``. So a route's variants do not depend on which other routes are
generated with it, nor on the worker count.

``--baseline-bank FILE``: LangAuto's own baseline wording (LMDrive's instruction dictionary) for
the instruction types it maps (:mod:`.baseline_bank`); validated before any route is touched,
its SHA-256 recorded in every route file and in ``index.json``.
"""

from __future__ import annotations

import zlib
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path

import numpy as np

from icrsumo.core.errors import Field, InputError, check_seed
from icrsumo.core.fsio import check_out_dir, dumps_json, write_atomic
from icrsumo.core.procs import spawn_context
from icrsumo.core.types import InstructionSet, Maneuver
from icrsumo.core.vocab import CONTROL_FAMILIES
from icrsumo.world.convert import safe_name
from icrsumo.world.networks import load_net
from icrsumo.world.scenario import Scenario, check_against_net, find_scenarios, read_scenario

from .banks import Banks, load_banks
from .baseline import LAYOUT_VERSION, build_baseline
from .baseline_bank import BaselineBank, load_baseline_bank
from .families import ALL_FAMILIES, FAMILIES, extend_variants, make_variants
from .maneuvers import extract_maneuvers, is_highway
from .store import FORMAT, route_document

DEFAULT_SEED = 2026
DEFAULT_K = 8


@dataclass(frozen=True)
class GenerateOptions:
    """What to generate. ``llm``: an LLMConfig to use an LLM instead of the template banks;
    ``baseline_bank``: a LangAuto-style instruction dictionary (a path, or one already loaded)
    whose phrasings the baseline uses for the types it maps."""

    families: tuple[str, ...] = FAMILIES
    k: int = DEFAULT_K
    seed: int = DEFAULT_SEED
    templates: Path | None = None
    workers: int = 1
    llm: object | None = None
    baseline_bank: Path | BaselineBank | None = None
    #: the K an out folder had before its --k grew, oldest first: the variants are drawn for the
    #: first K and extended step by step (:func:`icrsumo.instructions.families.extend_variants`)
    grown_from: tuple[int, ...] = ()

    def check(self) -> None:
        bad = [f for f in self.families if f not in ALL_FAMILIES]
        if bad or not self.families:
            raise InputError(Field("families"), "", f"unknown family {bad[0] if bad else '(none)'}",
                             f"use some of {', '.join(ALL_FAMILIES)}")
        if not 1 <= self.k <= 64:
            raise InputError(Field("k"), "", f"K={self.k} out of range", "use 1 to 64 (default 8)")
        if self.workers < 1:
            raise InputError(Field("workers"), "", "must be at least 1", "give a positive count")
        ks = (*self.grown_from, self.k)
        if any(a >= b for a, b in zip(ks, ks[1:])) or min(ks) < 1:
            grown = ", ".join(map(str, self.grown_from))
            raise InputError(Field("k"), str(self.k), f"cannot grow from K = {grown}",
                             f"give a larger {Field('k')} than the folder's")
        if self.grown_from and self.llm is not None:
            raise InputError(Field("k"), str(self.k), "a folder's K grows with the template banks only",
                             "generate the larger K into another folder")
        check_seed(self.seed)


@cache
def _banks(folder: str | None) -> Banks:
    return load_banks(Path(folder) if folder else None)


def route_rng(seed: int, route_id: str) -> np.random.Generator:
    """The Generator that drives every counterfactual draw of one route."""
    return np.random.default_rng([seed, zlib.crc32(route_id.encode("utf-8"))])


def grow_rng(seed: int, route_id: str, k_old: int, k_new: int) -> np.random.Generator:
    """The generator of the variants K = k_old .. k_new - 1 added when a folder's --k grows."""
    return np.random.default_rng([seed, zlib.crc32(route_id.encode("utf-8")), k_old, k_new])


def _highway_spans(sc: Scenario, net) -> tuple[tuple[float, float], ...]:
    """(start, end) route positions (m) of the route's highway edges."""
    cuts = [0.0] + [j.pos for j in sc.route.junctions] + [sc.length]
    return tuple((cuts[i], cuts[i + 1]) for i, e in enumerate(sc.ego_edges)
                 if i + 1 < len(cuts) and is_highway(net, e))


def baseline_set(sc: Scenario, banks: Banks, seed: int,
                 baseline_bank: BaselineBank | None = None) -> tuple[InstructionSet, list[Maneuver]]:
    """The baseline sequence of a scenario with phrasings drawn by ``seed`` (the protocol uses
    the route seed; data collection draws other phrasings), and the route's maneuvers;
    ``baseline_bank``: LangAuto's phrasings for the types it maps."""
    net = load_net(sc.net)
    check_against_net(sc, net)
    maneuvers = extract_maneuvers(sc, net)
    return build_baseline(sc.route_id, sc.length, maneuvers, banks, seed,
                          _highway_spans(sc, net), net.crossing_nodes, baseline_bank), maneuvers


def _baseline_bank(opts: GenerateOptions) -> BaselineBank | None:
    bank = opts.baseline_bank
    return load_baseline_bank(bank) if isinstance(bank, (str, Path)) else bank


def generate_route(scenario_dir: Path, opts: GenerateOptions) -> tuple[str, dict]:
    """The instruction document of one converted route."""
    sc = read_scenario(scenario_dir)
    banks = _banks(str(opts.templates) if opts.templates else None)
    user = _baseline_bank(opts)
    baseline, maneuvers = baseline_set(sc, banks, sc.seed, user)
    if opts.llm is None:
        ks = (*opts.grown_from, opts.k)
        variants = make_variants(baseline, opts.families, ks[0], banks, opts.seed,
                                 route_rng(opts.seed, sc.route_id))
        for k_old, k_new in zip(ks, ks[1:]):  # a folder whose --k grew: the old variants stay
            variants = extend_variants(baseline, variants, opts.families, k_new, banks, opts.seed,
                                       grow_rng(opts.seed, sc.route_id, k_old, k_new))
        generator = "templates"
    else:
        from .llm import llm_variants

        rng = route_rng(opts.seed, sc.route_id)  # the control families need no model
        variants = [v for fam in opts.families
                    for v in (make_variants(baseline, (fam,), opts.k, banks, opts.seed, rng)
                              if fam in CONTROL_FAMILIES
                              else llm_variants(baseline, fam, opts.k, opts.seed, opts.llm))]
        generator = f"llm:{opts.llm.model}"
    meta = {"seed": opts.seed, "k": opts.k, "families": list(opts.families),
            **({"grown_from": list(opts.grown_from)} if opts.grown_from else {}),
            "generator": generator, "layout": LAYOUT_VERSION, "banks_sha256": banks.sha256,
            **({"baseline_bank_sha256": user.sha256} if user is not None else {}),
            "scenario_hash": sc.source_hash}
    return sc.route_id, route_document(baseline, variants, maneuvers, meta)


def _job(args: tuple[str, GenerateOptions]) -> tuple[str, str, str | InputError]:
    """("ok", route id, its document's JSON) or ("failed", folder, the InputError)."""
    d, opts = args
    try:
        rid, doc = generate_route(Path(d), opts)
        return "ok", rid, dumps_json(doc)
    except InputError as err:
        return "failed", d, err
    except Exception as err:  # an LLM route that failed after its retries
        from .llm import LLMError

        if isinstance(err, LLMError):
            return "failed", d, InputError(d, "LLM", " ".join(str(err).split())[:300],
                                           f"check {Field('endpoint')} and {Field('model')}, and that the "
                                           "server answers")
        raise


def generate(scenarios: Path, out: Path, opts: GenerateOptions,
             refuse_empty: bool = False) -> tuple[list[str], list[InputError]]:
    """Write ``OUT/<route>.json`` per route and ``OUT/index.json``; returns (route ids written,
    the InputError of every route that failed: ``str(err)`` is its line). Template banks are
    validated before any route is touched. With ``refuse_empty``, a run in which no route could
    be generated writes nothing and raises the first route's InputError."""
    opts.check()
    scenarios = Path(scenarios)
    check_out_dir(Path(out))
    if (scenarios / "scenario.json").is_file():
        dirs = [scenarios]
    elif scenarios.is_dir():
        dirs = find_scenarios(scenarios)
    else:
        dirs = []
    if not dirs:
        raise InputError(scenarios, "", "no converted scenarios found",
                         "run icrsumo convert-routes ROUTES --out DIR first and pass DIR")
    _banks(str(opts.templates) if opts.templates else None)  # validate up front
    user = _baseline_bank(opts)  # read and validated once, before any route
    opts = replace(opts, baseline_bank=user)
    jobs = [(str(d), opts) for d in dirs]
    if opts.workers > 1 and len(jobs) > 1:
        # spawned, not forked (see icrsumo.world.convert.convert_routes)
        with ProcessPoolExecutor(max_workers=min(opts.workers, len(jobs)),
                                 mp_context=spawn_context()) as pool:
            results = list(pool.map(_job, jobs))
    else:
        results = [_job(j) for j in jobs]
    if refuse_empty and results and all(status != "ok" for status, _, _ in results):
        raise results[0][2]  # nothing to write: the (first) reason
    written, failures, index = [], [], []
    for status, rid, payload in results:
        if status != "ok":
            failures.append(payload)
            continue
        name = f"{safe_name(rid)}.json"
        write_atomic(Path(out) / name, payload)
        written.append(rid)
        index.append({"route_id": rid, "file": name})
    write_atomic(Path(out) / "index.json", dumps_json({
        "format": FORMAT.replace("instructions", "instruction-index"), "seed": opts.seed,
        "k": opts.k, "families": list(opts.families), "routes": index,
        "failures": [err.line() for err in failures],
        **({"baseline_bank": user.describe()} if user is not None else {}),
    }))
    return written, failures
