"""The options of one evaluation and their validation (pure: no user code is imported here;
agent specs are resolved by the orchestration, :mod:`icrsumo.evaluation.run`)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from icrsumo.agents.registry import DEFAULT_AGENT
from icrsumo.core.devices import check_device
from icrsumo.core.errors import Field, InputError, check_seed
from icrsumo.core.fsio import check_out_dir
from icrsumo.guards.base import check_policy
from icrsumo.instructions.baseline_bank import load_baseline_bank
from icrsumo.instructions.families import ALL_FAMILIES, FAMILIES
from icrsumo.scoring import SCORINGS, scoring_names
from icrsumo.world.routes import suite_file
from icrsumo.world.traffic import TRAFFIC_LEVELS

#: execution backends: a local process pool, or Ray
BACKENDS = ("local", "ray")
#: seconds an agent's reset / act call may take by default (``agent_timeout``)
AGENT_TIMEOUT = 60.0


@dataclass(frozen=True)
class EvalOptions:
    """One evaluation. ``routes``: a subset of route ids (None: all). ``agent_timeout``: s an
    agent's reset / act call may take (None: no limit, and ``workers=1`` runs in-process)."""

    out: Path
    suite: str = "tiny"
    agents: tuple[str, ...] = (DEFAULT_AGENT,)
    families: tuple[str, ...] = FAMILIES
    k: int = 8
    seed: int = 2026
    routes: tuple[str, ...] | None = None
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    backend: str = "local"
    address: str | None = None
    traffic: str = "normal"
    quiet: bool = False
    rollout_route: str | None = None
    agent_timeout: float | None = AGENT_TIMEOUT
    #: device of one batched inference process per non-privileged agent (None: every worker
    #: runs its own agent), e.g. "cuda"; ``max_batch``: observations per forward pass
    batch_inference: str | None = None
    max_batch: int = 32
    #: inference processes per agent with ``batch_inference`` (each worker uses one)
    inference_processes: int = 1
    #: device of the learned agents that the episode workers run themselves (None: their
    #: default, cpu); with ``batch_inference`` the inference processes use that device instead
    agent_device: str | None = None
    #: LangAuto's own baseline wording (LMDrive's instruction dictionary, a JSON file) for the
    #: instruction types it maps; part of the out folder's configuration through its SHA-256
    baseline_bank: Path | str | None = None
    #: run the stored crashed episodes again (a transient fault repaired in place)
    retry_crashed: bool = False
    #: the scoring rules (``--scoring``): a name of :data:`icrsumo.scoring.SCORINGS`; part of the
    #: out folder's configuration
    scoring: str = "lb1"
    #: agent names whose stored episodes (of another fingerprint) are deleted and run again
    replace_agents: tuple[str, ...] = ()
    #: instruction guards (``--guard``): every agent also runs behind each, as its own rows
    #: ``AGENT+guard:NAME`` (:mod:`icrsumo.guards`)
    guards: tuple[str, ...] = ()
    #: asking for clarification (``--asking``): the navigator answers agents' asks
    #: (``Action.ask``; :mod:`icrsumo.sim.asking`); part of the out folder's configuration
    asking: bool = False
    #: what an instruction a guard blocks leaves the agent (``--on-block``): ``keep``, what it was
    #: shown before; ``navigator``, the navigation plan's instruction in the route's baseline words,
    #: in rows ``AGENT+guard:NAME+navigator`` (:mod:`icrsumo.guards.stream`); part of the out
    #: folder's configuration
    on_block: str = "keep"
    #: time the run's phases (``EvalResult.profile``, :mod:`icrsumo.evaluation.profile`: for
    #: ``tools/benchmark.py --protocol``); never stored, the results are the same
    profile: bool = False

    def check(self) -> None:
        """InputErrors for bad values (agent specs are checked when they are resolved); first
        the types (the Python API passes any object: ``k='1'`` is named, not a TypeError)."""
        self._check_types()
        bad = [f for f in self.families if f not in ALL_FAMILIES]
        if bad or not self.families:
            raise InputError(Field("families"), bad[0] if bad else "", "unknown family",
                             f"use {', '.join(ALL_FAMILIES)}")
        if self.backend not in BACKENDS:
            raise InputError(Field("backend"), self.backend, "unknown backend", "use local or ray")
        if not 1 <= self.k <= 64:
            raise InputError(Field("k"), str(self.k), "out of range", "use 1 to 64 (default 8)")
        check_seed(self.seed)
        if self.max_batch < 1:
            raise InputError(Field("max_batch"), str(self.max_batch), "must be at least 1",
                             "give a positive count")
        if self.workers < 1:
            raise InputError(Field("workers"), str(self.workers), "must be at least 1",
                             "give a positive count")
        if self.agent_timeout is not None and not 0 < self.agent_timeout < float("inf"):
            raise InputError(Field("agent_timeout"), str(self.agent_timeout), "must be positive",
                             "give seconds per agent call (0 on the command line: no limit)")
        check_out_dir(Path(self.out))
        if self.address is not None and self.backend != "ray":
            raise InputError(Field("address"), self.address, "is for the ray backend",
                             f"add {Field('backend')} ray")
        if self.batch_inference is not None:
            check_device(self.batch_inference, Field("batch_inference"))
            if self.backend != "local":
                raise InputError(Field("batch_inference"), self.batch_inference,
                                 "works with the local backend only (its workers reach the inference "
                                 "process through a Unix socket)",
                                 f"use {Field('backend')} local")
            if self.inference_processes < 1:
                raise InputError(Field("inference_processes"), str(self.inference_processes),
                                 "must be at least 1", "give a positive count")
        if self.agent_device is not None:
            check_device(self.agent_device, Field("agent_device"))
        if self.scoring not in SCORINGS:
            raise InputError(Field("scoring"), str(self.scoring), "unknown scoring",
                             f"use {', '.join(scoring_names())}")
        if self.traffic not in TRAFFIC_LEVELS:
            raise InputError(Field("traffic"), str(self.traffic), "unknown traffic level",
                             f"use {', '.join(TRAFFIC_LEVELS)}")
        check_policy(self.on_block)
        if self.on_block != "keep" and not self.guards:
            raise InputError(Field("on_block"), self.on_block,
                             "applies to guarded rows, and no guard is given",
                             f"add {Field('guards')} NAME, or leave {Field('on_block')} out")
        if self.baseline_bank is not None:
            load_baseline_bank(self.baseline_bank)  # an InputError for a bad file, before anything runs
        suite_file(self.suite, folders=True)  # a missing file named as one, not a suite

    def _check_types(self) -> None:
        for name in ("k", "seed", "workers", "max_batch", "inference_processes"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int):
                raise InputError(Field(name), repr(v)[:40], f"must be an integer, not {type(v).__name__}",
                                 "give a whole number")
        for name in ("quiet", "retry_crashed", "asking", "profile"):
            if not isinstance(getattr(self, name), bool):
                raise InputError(Field(name), repr(getattr(self, name))[:40], "must be True or False",
                                 "give a bool")
        for name in ("suite", "backend", "traffic", "scoring", "on_block"):
            v = getattr(self, name)
            if not isinstance(v, str):
                raise InputError(Field(name), repr(v)[:40], f"must be a string, not {type(v).__name__}",
                                 "give its name")
        t = self.agent_timeout
        if t is not None and (isinstance(t, bool) or not isinstance(t, (int, float))):
            raise InputError(Field("agent_timeout"), repr(t)[:40], "must be a number of seconds or None",
                             "give e.g. 60, or None for no limit")
        for name in ("families", "guards", "replace_agents"):
            values = getattr(self, name)
            if not isinstance(values, tuple) or not all(isinstance(v, str) for v in values):
                raise InputError(Field(name), repr(values)[:60], "must be names (strings)",
                                 "give a name or a list of names")

