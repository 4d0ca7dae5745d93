"""``icrsumo generate``: baseline sequence + K variants per family for every converted route.

Randomness: phrasings of the baseline come from a Generator seeded with the route's seed (from
the scenario); every counterfactual draw of a route comes from one Generator seeded with
``(--seed, crc32(route id))``. So a route's variants do not depend on which other routes are
generated with it, nor on the worker count. The delivery families (timing, distance,
correction, notice: :mod:`.delivery`) draw from Generators of their own, so selecting them
changes no other family's variants; a route one of them cannot be built for is named and
skipped for it (the index's ``skipped``).

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

from icrsumo.core.errors import Field, InputError, check_seed, note
from icrsumo.core.fsio import check_out_dir, dumps_json, write_atomic
from icrsumo.core.procs import spawn_context
from icrsumo.core.types import InstructionSet, Maneuver
from icrsumo.core.vocab import CONTROL_FAMILIES, DELIVERY_FAMILIES, variants_of
from icrsumo.world.convert import safe_name
from icrsumo.world.networks import load_net
from icrsumo.world.scenario import Scenario, check_against_net, find_scenarios, read_scenario

from .banks import Banks, load_banks
from .baseline import LAYOUT_VERSION, build_baseline
from .baseline_bank import BaselineBank, load_baseline_bank
from .delivery import DeliveryParams, RouteView, Unbuildable, delivery_variants
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
    #: the delivery families' parameters (:class:`icrsumo.instructions.delivery.DeliveryParams`)
    delivery: DeliveryParams = DeliveryParams()

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
        self.delivery.check()


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


def baseline_set(sc: Scenario, banks: Banks, seed: int, baseline_bank: BaselineBank | None = None,
                 lead_rng: np.random.Generator | None = None) -> tuple[InstructionSet, list[Maneuver]]:
    """The baseline sequence of a scenario with phrasings drawn by ``seed`` (the protocol uses
    the route seed; data collection draws other phrasings), and the route's maneuvers;
    ``baseline_bank``: LangAuto's phrasings for the types it maps; ``lead_rng``: varied
    announcement distances (training data only, :func:`.baseline.build_baseline`)."""
    net = load_net(sc.net)
    check_against_net(sc, net)
    maneuvers = extract_maneuvers(sc, net)
    return build_baseline(sc.route_id, sc.length, maneuvers, banks, seed,
                          _highway_spans(sc, net), net.crossing_nodes, baseline_bank,
                          lead_rng), maneuvers


def _baseline_bank(opts: GenerateOptions) -> BaselineBank | None:
    bank = opts.baseline_bank
    return load_baseline_bank(bank) if isinstance(bank, (str, Path)) else bank


def _wording_variants(baseline: InstructionSet, sc: Scenario, banks: Banks, opts: GenerateOptions,
                      families: tuple[str, ...]) -> tuple[list[InstructionSet], str]:
    """The variants of the wording families (the paper's four and the controls) and the
    generator that wrote them."""
    if opts.llm is None:
        ks = (*opts.grown_from, opts.k)
        variants = make_variants(baseline, families, ks[0], banks, opts.seed,
                                 route_rng(opts.seed, sc.route_id))
        for k_old, k_new in zip(ks, ks[1:]):  # a folder whose --k grew: the old variants stay
            variants = extend_variants(baseline, variants, families, k_new, banks, opts.seed,
                                       grow_rng(opts.seed, sc.route_id, k_old, k_new))
        return variants, "templates"
    from .llm import llm_variants

    rng = route_rng(opts.seed, sc.route_id)  # the control families need no model
    return [v for fam in families
            for v in (make_variants(baseline, (fam,), opts.k, banks, opts.seed, rng)
                      if fam in CONTROL_FAMILIES
                      else llm_variants(baseline, fam, opts.k, opts.seed, opts.llm))], f"llm:{opts.llm.model}"


def _delivery_variants(baseline: InstructionSet, maneuvers: list[Maneuver], sc: Scenario, banks: Banks,
                       opts: GenerateOptions) -> tuple[dict[str, list[InstructionSet]], dict[str, str]]:
    """The variants of the selected delivery families (from the templates, also under an LLM
    generator: they change when and how, not the words), and why each family that cannot be
    built for the route is skipped."""
    built: dict[str, list[InstructionSet]] = {}
    skipped: dict[str, str] = {}
    selected = [f for f in opts.families if f in DELIVERY_FAMILIES]
    if not selected:
        return built, skipped
    view = RouteView(baseline, tuple(maneuvers), sc.route.junctions, load_net(sc.net), sc.length)
    for fam in selected:
        try:
            built[fam] = delivery_variants(fam, view, range(variants_of(fam, opts.k)), opts.seed, banks,
                                           opts.delivery)
        except Unbuildable as why:
            skipped[fam] = str(why)
    return built, skipped


def generate_route(scenario_dir: Path, opts: GenerateOptions) -> tuple[str, dict]:
    """The instruction document of one converted route (a delivery family it cannot be built
    for is left out and named in its ``skipped``)."""
    sc = read_scenario(scenario_dir)
    banks = _banks(str(opts.templates) if opts.templates else None)
    user = _baseline_bank(opts)
    baseline, maneuvers = baseline_set(sc, banks, sc.seed, user)
    wording = tuple(f for f in opts.families if f not in DELIVERY_FAMILIES)
    variants, generator = _wording_variants(baseline, sc, banks, opts, wording)
    built, skipped = _delivery_variants(baseline, maneuvers, sc, banks, opts)
    variants = [s for fam in opts.families for s in (built.get(fam, []) if fam in DELIVERY_FAMILIES
                                                      else [v for v in variants if v.family == fam])]
    delivery = any(f in DELIVERY_FAMILIES for f in opts.families)
    meta = {"seed": opts.seed, "k": opts.k, "families": list(opts.families),
            **({"grown_from": list(opts.grown_from)} if opts.grown_from else {}),
            "generator": generator, "layout": LAYOUT_VERSION, "banks_sha256": banks.sha256,
            **({"baseline_bank_sha256": user.sha256} if user is not None else {}),
            "scenario_hash": sc.source_hash,
            **({"delivery": opts.delivery.to_dict()} if delivery else {}),
            **({"skipped": skipped} if skipped else {})}
    return sc.route_id, route_document(baseline, variants, maneuvers, meta)


def _job(args: tuple[str, GenerateOptions]) -> tuple[str, str, tuple[str, dict[str, str]] | InputError]:
    """("ok", route id, (its document's JSON, the families skipped: why)) or ("failed",
    folder, the InputError)."""
    d, opts = args
    try:
        rid, doc = generate_route(Path(d), opts)
        return "ok", rid, (dumps_json(doc), doc.get("skipped", {}))
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
    the InputError of every route that failed: ``str(err)`` is its line). A delivery family
    that cannot be built for a route is named on stderr (one line: the route and why) and
    listed in the index's ``skipped`` (route id, family, why). Template banks are
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
    written, failures, index, skipped = [], [], [], []
    for status, rid, payload in results:
        if status != "ok":
            failures.append(payload)
            continue
        text, left_out = payload
        name = f"{safe_name(rid)}.json"
        write_atomic(Path(out) / name, text)
        written.append(rid)
        index.append({"route_id": rid, "file": name})
        for fam, why in left_out.items():
            note(f"route {rid}: family {fam} cannot be built: {why}; the route is skipped for it")
            skipped.append({"route_id": rid, "family": fam, "why": why})
    write_atomic(Path(out) / "index.json", dumps_json({
        "format": FORMAT.replace("instructions", "instruction-index"), "seed": opts.seed,
        "k": opts.k, "families": list(opts.families), "routes": index,
        "failures": [err.line() for err in failures],
        **({"baseline_bank": user.describe()} if user is not None else {}),
        **({"skipped": skipped} if skipped else {}),
    }))
    return written, failures
