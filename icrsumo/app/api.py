"""The Python API: what the ``icrsumo`` command does, callable from a notebook or another tool.

* :func:`evaluate`: the paired ICR protocol (``icrsumo evaluate``), returning an
  :class:`~icrsumo.evaluation.EvalResult`;
* :func:`load_suite`: a route suite converted and with its instructions, as a :class:`Suite`;
* :func:`run_episode`: one closed-loop episode (:func:`icrsumo.sim.episode.run_episode`), with
  an agent given as an object or a spec;
* :func:`digest` and :func:`compare_digests`: an evaluation folder's digest (``icrsumo digest``,
  :mod:`icrsumo.evaluation.digests`), and two runs compared by it.

All five are exported lazily by :mod:`icrsumo` (``icrsumo.evaluate(...)``). Bad input raises
:class:`icrsumo.core.errors.InputError`, whose message names fields by their keywords (the CLI
prints the same line naming its options).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

from icrsumo.core.errors import Field, InputError

if TYPE_CHECKING:
    from icrsumo.agents.base import Agent
    from icrsumo.core.types import EpisodeLog, InstructionSet
    from icrsumo.evaluation import EvalOptions, EvalResult
    from icrsumo.evaluation.digests import Comparison
    from icrsumo.sim.callbacks import EpisodeCallback
    from icrsumo.sim.episode import RunOptions
    from icrsumo.world.scenario import Scenario

__all__ = ["Suite", "compare_digests", "digest", "evaluate", "load_suite", "run_episode"]


def _names(value: str | Sequence[str] | None) -> tuple[str, ...] | None:
    """One name or several (a str, or a sequence of str) as a tuple of plain str; None stays
    None."""
    if value is None:
        return None
    return (str(value),) if isinstance(value, str) else tuple(str(v) for v in value)


def _agents(value: Any) -> tuple | None:
    """``agents`` as a tuple: specs (str) and agents given as Python objects (a class, a
    function making agents, an instance) as they are; None stays None."""
    if value is None:
        return None
    if isinstance(value, str) or not isinstance(value, (list, tuple)):
        return (value,)
    return tuple(value)


def _options(out: str | Path, suite: str | Path, **given: Any) -> EvalOptions:
    from icrsumo.evaluation import EvalOptions

    known = {f.name for f in fields(EvalOptions)}
    unknown = sorted(set(given) - known)
    if unknown:
        raise TypeError(f"unknown evaluation option {unknown[0]!r} "
                        f"(known: {', '.join(sorted(known - {'out'}))})")
    values = {k: v for k, v in given.items() if v is not None or k in ("agent_timeout", "routes")}
    return EvalOptions(out=Path(out), suite=str(suite), **values)


def evaluate(suite: str | Path = "tiny", agents: str | Sequence[str] | None = None,
             families: str | Sequence[str] | None = None, k: int = 8, seed: int = 2026,
             out: str | Path = "icr_out", workers: int | None = None, quiet: bool = True,
             **more: Any) -> EvalResult:
    """Run (or resume) the paired ICR protocol and write its reports into ``out``.

    For every agent and route of ``suite``: the baseline instructions and ``k`` variants of each
    of ``families`` (default: all four), all on the same scenario, seed and traffic; every
    episode is stored in ``out/results.sqlite`` as it ends, so a rerun with the same options
    runs only what is missing. ``suite``: tiny, short, long, a route XML file or a convert-routes
    folder; ``agents``: one agent or a list of them, each a spec (a registered name such as
    ``route-oracle``, ``module:Class``, ``path/file.py:Class``, ``remote:http://HOST:PORT``), an
    agent class or a function that makes agents, or an agent instance (copied afresh for every
    episode); default: the default agent of ``icrsumo evaluate``; ``workers``: worker processes
    (default: the number of cores); ``quiet``: no progress bar and no table on the terminal.
    ``more``: the other fields of :class:`icrsumo.evaluation.EvalOptions`: ``routes`` (route ids),
    ``backend`` (local, ray), ``address``, ``traffic``, ``rollout_route``, ``agent_timeout`` (s,
    None: no limit), ``batch_inference`` (a device), ``max_batch``, ``inference_processes``,
    ``agent_device``, ``baseline_bank`` (LMDrive's instruction dictionary: LangAuto's own baseline
    wording, part of the folder's configuration), ``scoring`` (``lb1``: CARLA Leaderboard 1.0's
    rules, part of the folder's configuration), ``replace_agents`` (names whose stored episodes
    another agent of that name drove are deleted and run again), ``retry_crashed``, ``guards``
    (instruction guards, e.g. ``"plan"`` or ``["text", "plan"]``: every agent also runs behind each,
    as its own rows ``AGENT+guard:NAME``; :mod:`icrsumo.guards`), ``on_block`` (what an instruction
    a guard blocks leaves the agent: ``"keep"``, what it was shown before, or ``"navigator"``, the
    navigation plan's instruction in the route's baseline words, in rows ``AGENT+guard:NAME+navigator``;
    part of the folder's configuration), ``asking`` (the navigator answers
    agents' asks for clarification, :mod:`icrsumo.sim.asking`; part of the folder's configuration),
    ``profile`` (the run's wall time split into phases, :mod:`icrsumo.evaluation.profile`; never stored).

    Returns an :class:`icrsumo.evaluation.EvalResult`: ``summary`` (OUT/summary.json),
    ``out``, the episode counts, the batched-inference statistics and, with ``profile``, the profile. Raises
    :class:`icrsumo.core.errors.InputError` for bad input (nothing is written then) and TypeError
    for an unknown option.
    """
    from icrsumo.evaluation import run_evaluation

    if "routes" in more:
        more["routes"] = _names(more["routes"]) or None
    if "replace_agents" in more:
        more["replace_agents"] = _names(more["replace_agents"]) or ()
    if "guards" in more:
        more["guards"] = _names(more["guards"]) or ()
    opts = _options(out, suite, agents=_agents(agents), families=_names(families), k=k, seed=seed,
                    workers=workers, quiet=quiet, **more)
    return run_evaluation(opts)


@dataclass(frozen=True)
class Suite:
    """A route suite ready to run: ``scenarios`` (the converted routes, in suite order, that
    have instructions), ``instruction_sets`` (route id -> its baseline sequence first, then the
    variants of every family, k = 0 .. K-1), the folders they were read from and the lines of
    the routes that were skipped."""

    name: str
    out: Path
    scenarios: tuple[Scenario, ...]
    instruction_sets: Mapping[str, tuple[InstructionSet, ...]]
    scenarios_dir: Path
    instructions_dir: Path
    skipped: tuple[str, ...] = ()

    @property
    def route_ids(self) -> tuple[str, ...]:
        """The route ids, in suite order."""
        return tuple(sc.route_id for sc in self.scenarios)

    def scenario(self, route_id: str) -> Scenario:
        """The scenario of ``route_id`` (KeyError naming the suite's routes)."""
        for sc in self.scenarios:
            if sc.route_id == route_id:
                return sc
        raise KeyError(f"no route {route_id!r} in suite {self.name} (routes: {', '.join(self.route_ids)})")

    def instruction_set(self, route_id: str, family: str = "baseline", k: int = 0) -> InstructionSet:
        """The instruction sequence of ``route_id`` for ``family`` and variant ``k`` (the
        baseline has k = 0); KeyError when there is none."""
        for s in self.instruction_sets[route_id]:
            if s.family == family and s.k == k:
                return s
        raise KeyError(f"route {route_id!r} has no {family} sequence k={k}")


def load_suite(suite: str | Path = "tiny", out: str | Path = "icr_out", *, k: int = 8, seed: int = 2026,
               traffic: str = "normal", workers: int | None = None,
               baseline_bank: str | Path | None = None) -> Suite:
    """Convert ``suite`` into ``out`` and generate its instructions, as ``evaluate`` does.

    ``suite``: tiny, short, long, a route XML file or a convert-routes folder (used as it is);
    ``k`` variants per family with ``seed``, ``traffic``, ``workers`` and ``baseline_bank`` as
    in :func:`evaluate`.
    Whatever is in ``out`` already is reused, and ``out/config.json`` is written, so an
    :func:`evaluate` into the same ``out`` with the same suite, k, seed and traffic reuses it
    (an InputError when ``out`` holds another configuration). Returns a :class:`Suite`.
    """
    from icrsumo.evaluation import plan
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.world.convert import safe_name
    from icrsumo.world.scenario import find_scenarios, read_scenario

    opts = _options(out, suite, k=k, seed=seed, traffic=traffic, workers=workers, quiet=True,
                    baseline_bank=baseline_bank)
    opts.check()
    prep = plan.prepare_suite(opts)
    written = set(prep.routes)
    scenarios = tuple(sc for sc in (read_scenario(d) for d in find_scenarios(prep.scenarios))
                      if sc.route_id in written)
    sets = {sc.route_id: tuple(read_instruction_sets(prep.instructions / f"{safe_name(sc.route_id)}.json"))
            for sc in scenarios}
    return Suite(name=str(suite), out=Path(out), scenarios=scenarios, instruction_sets=sets,
                 scenarios_dir=prep.scenarios, instructions_dir=prep.instructions, skipped=prep.skipped)


def run_episode(scenario: Scenario | str | Path, instruction_set: InstructionSet, agent: Agent | str,
                options: RunOptions | None = None,
                callbacks: Sequence[EpisodeCallback] = (),
                baseline: InstructionSet | None = None) -> EpisodeLog:
    """Drive one closed-loop episode and return its :class:`~icrsumo.core.types.EpisodeLog`.

    ``scenario``: a :class:`~icrsumo.world.scenario.Scenario` or a convert-routes scenario folder;
    ``instruction_set``: one of its route's sequences (:meth:`Suite.instruction_set`);
    ``agent``: an agent object (``reset(info)``, ``act(obs)``) or a spec as in :func:`evaluate`
    (a fresh agent is made); ``options``: :class:`icrsumo.sim.RunOptions` (agent rate, BEV
    spec, ``asking``); ``callbacks``: :class:`icrsumo.sim.EpisodeCallback` side effects (timings,
    video, your own); ``baseline``: the route's baseline sequence, whose words answer asks with
    ``asking`` on (not needed when ``instruction_set`` is the baseline). Score it with
    :func:`icrsumo.scoring.score_episode`.
    Raises :class:`icrsumo.core.errors.InputError` before the episode starts for a scenario whose
    manifest and network disagree, or an ``instruction_set`` of another route."""
    from icrsumo.agents.registry import make_agent
    from icrsumo.sim.episode import RunOptions
    from icrsumo.sim.episode import run_episode as _run
    from icrsumo.world.networks import load_net
    from icrsumo.world.scenario import check_against_net, read_scenario

    sc = scenario if not isinstance(scenario, (str, Path)) else read_scenario(Path(scenario))
    check_against_net(sc, load_net(sc.net))
    if instruction_set.route_id != sc.route_id:
        raise InputError(Field("instruction_set"), f"route {instruction_set.route_id!r}",
                         f"is not a sequence of the scenario's route {sc.route_id!r}",
                         "pass the instructions generated for this scenario")
    instance = make_agent(agent) if isinstance(agent, str) else agent
    return _run(sc, instruction_set, instance, options or RunOptions(), callbacks, baseline=baseline)


def digest(out: str | Path = "icr_out") -> str:
    """The digest of the evaluation folder ``out`` (``sha256:`` and 64 hex digits): one SHA-256
    over every episode in ``out/results.sqlite`` (its stored log, or a crashed episode's status
    and message) and the folder's scoring, computed from the store (:mod:`icrsumo.evaluation.digests`
    defines the bytes). The same digest on another machine means every episode is the same.
    Raises :class:`icrsumo.core.errors.InputError` for a folder that is not an evaluation folder or
    a damaged store."""
    from icrsumo.evaluation.digests import folder_digest

    return folder_digest(Path(out)).digest


def compare_digests(out: str | Path, other: str | Path) -> Comparison:
    """Compare the evaluation folder ``out`` with ``other``, a second folder or a digest
    (``sha256:HEX`` or 64 hex digits): a :class:`icrsumo.evaluation.digests.Comparison` (``same``, both
    digests and, for two folders that differ, ``first_difference``: the first episode in key
    order stored in one only or with another log). Two folders of different scorings or suites,
    and an ``other`` that is neither a folder nor a digest, raise
    :class:`icrsumo.core.errors.InputError`."""
    from icrsumo.evaluation.digests import compare

    return compare(Path(out), other)
