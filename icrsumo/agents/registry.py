"""The agent registry and agent specs.

An agent is named by a *spec*: a registered name (the built-ins: ``route-oracle``,
``instruction-follower`` and the learned agents whose checkpoints ship), ``module:Class``,
``path/file.py:Class``, ``remote:http://HOST:PORT`` or ``llm:MODEL@http://HOST:PORT/v1``.
:func:`agent_factory` turns a spec into a zero-argument factory of fresh agents (InputErrors
for bad specs).

Names are registered explicitly with :func:`register`, which refuses a name that is already
taken (as Gymnasium's environment registry and waymax's metric registry do)::

    from icrsumo.agents.registry import register
    register("my-agent", MyAgent, description="drives from the BEV raster")

A factory with a ``device`` keyword (the learned agents: ``LearnedAgent(checkpoint,
device="cpu")``) is built on another device with ``agent_factory(spec, device="cuda")``.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import inspect
import sys
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from icrsumo.core.defaults import DEFAULT_AGENT as _DEFAULT
from icrsumo.core.errors import Field, InputError

from .base import Agent
from .identity import PATH_MODULE_PREFIX

#: ``remote:http://HOST:PORT``: an agent behind an icrsumo-agent/1 server (icrsumo.agents.remote)
REMOTE_PREFIX = "remote:"
#: ``llm:MODEL@http://HOST:PORT/v1``: the instruction-follower with a language model as its
#: interpreter (icrsumo.agents.llm)
LLM_PREFIX = "llm:"


@dataclass(frozen=True)
class AgentEntry:
    """A registered agent: its ``name`` (the spec), its ``factory`` (a zero-argument callable,
    usually the agent class; None until a lazy entry is first asked for), ``target``
    (``module:attr`` a lazy entry imports then) and a one-line ``description``; ``plugin``: the
    distribution that declared it in the ``icrsumo.agents`` entry-point group ("" for others)."""

    name: str
    factory: Callable[..., Agent] | None
    description: str = ""
    target: str = ""
    plugin: str = ""


#: the entry-point group through which installed packages add agents (``pip install my-agent``
#: makes ``--agent NAME`` work): ``[project.entry-points."icrsumo.agents"] NAME = "module:Class"``
ENTRY_POINT_GROUP = "icrsumo.agents"


class AgentRegistry(Mapping[str, Callable[..., Agent]]):
    """Registered agent names -> their factories (read-only as a mapping; change it with
    :meth:`register` and :meth:`unregister`). An entry given as ``"module:attr"`` is imported
    only when it is first asked for, so the registry imports no agent module of its own."""

    #: what its entries are, and the field that names one (for messages)
    kind = "agent"
    option = Field("agents")

    def __init__(self) -> None:
        self._entries: dict[str, AgentEntry] = {}
        #: plugin entry points that could not be registered: (name, distribution, why)
        self.skipped_plugins: list[tuple[str, str, str]] = []

    def register(self, name: str, factory: Callable[..., Agent] | str, *, description: str = "",
                 plugin: str = "") -> AgentEntry:
        """Register ``factory`` (a callable, or ``"module:attr"`` imported when first asked
        for) under ``name``; a ValueError when the name is taken or not a valid spec (empty,
        with whitespace, or with ``:``, which marks module:Class and remote specs), a TypeError
        when ``factory`` is neither callable nor a ``module:attr`` string."""
        if not isinstance(name, str) or not name or ":" in name or any(c.isspace() for c in name):
            raise ValueError(f"{self.kind} name {name!r} is not valid: use a non-empty name without ':' or "
                             f"whitespace, e.g. 'my-{self.kind}'")
        lazy = isinstance(factory, str)
        if lazy and factory.count(":") != 1:
            raise TypeError(f"cannot register {self.kind} {name!r}: {factory!r} is not 'module:attr'")
        if not lazy and not callable(factory):
            raise TypeError(f"cannot register {self.kind} {name!r}: its factory {factory!r} is not callable "
                            f"(pass the {self.kind} class or a zero-argument function)")
        old = self._entries.get(name)
        if old is not None:
            by = old.target or _qualname(old.factory)
            raise ValueError(f"{self.kind} {name!r} is already registered (by {by}): pick "
                             f"another name, or unregister({name!r}) first")
        entry = AgentEntry(name, None if lazy else factory, description, factory if lazy else "", plugin)
        self._entries[name] = entry
        return entry

    def unregister(self, name: str) -> AgentEntry:
        """Remove ``name`` (KeyError naming the registered ones when it is not registered)."""
        try:
            return self._entries.pop(name)
        except KeyError:
            raise KeyError(f"{self.kind} {name!r} is not registered "
                           f"(registered: {', '.join(self)})") from None

    def entry(self, name: str) -> AgentEntry:
        return self._entries[name]

    def __getitem__(self, name: str) -> Callable[..., Agent]:
        entry = self._entries[name]
        if entry.factory is None:
            entry = self._entries[name] = replace(entry, factory=_load_target(name, entry, self.option))
        return entry.factory

    def __contains__(self, name: object) -> bool:  # without loading a lazy entry
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)


def _load_target(name: str, entry: AgentEntry, option: Field = Field("agents")) -> Callable[..., Agent]:
    """The factory a lazy entry names (an InputError naming the entry under ``option`` when it
    cannot load)."""
    module, _, attr = entry.target.partition(":")
    where = f" (plugin of {entry.plugin})" if entry.plugin else ""
    try:
        obj = importlib.import_module(module)
        for part in attr.split("."):
            obj = getattr(obj, part)
    except BaseException as err:  # noqa: BLE001 - the plugin's (or our) module failed to import, or
        # raised SystemExit / KeyboardInterrupt in its body (as load_class: never a run that ends
        # silently having done nothing)
        why = f"{type(err).__name__}: {err}" if not isinstance(err, SystemExit) else \
            f"its import called sys.exit({err.code!r})"
        raise InputError(option, name, f"cannot load {entry.target}{where} ({why})",
                         "reinstall the package that provides it, or fix its module") from None
    if not callable(obj):
        raise InputError(option, name, f"{entry.target}{where} is not callable", "name the class")
    return obj


def _qualname(obj: object) -> str:
    return f"{getattr(obj, '__module__', '?')}.{getattr(obj, '__qualname__', type(obj).__name__)}"


#: the process's agent registry
REGISTRY = AgentRegistry()
register = REGISTRY.register
unregister = REGISTRY.unregister
#: registered name -> factory (the registry as a read-only mapping; the name older callers use)
BUILTIN: Mapping[str, Callable[..., Agent]] = REGISTRY


#: the shipped checkpoints' folder (found without importing the learned agents)
CHECKPOINTS_DIR = Path(__file__).resolve().parents[1] / "learn" / "checkpoints"

register("route-oracle", "icrsumo.agents.privileged:RouteOracle",
         description="privileged: follows the scenario's route (an upper reference)")
register("instruction-follower", "icrsumo.agents.privileged:InstructionFollower",
         description="privileged: follows the instructions as a careful driver would")
# learned agents whose exact checkpoints ship with the package (loaded on first use, no torch)
for _name, _cls, _doc in (
        ("bev-token", "TokenAgent", "word-token GRU language encoder, trained on baseline phrasings only."),
        ("bev-ngram", "NgramAgent", "hashed character n-gram language encoder, baseline phrasings only."),
        ("bev-ngram-aug", "NgramAugAgent", "as bev-ngram, trained with --augment-instructions."),
        ("bev-minilm", "MinilmAgent", "pretrained sentence encoder all-MiniLM-L6-v2 (frozen) + MLP, baseline "
         "phrasings only (needs icrsumo[minilm])."),
        ("bev-minilm-aug", "MinilmAugAgent", "as bev-minilm, trained with --augment-instructions.")):
    if (CHECKPOINTS_DIR / f"{_name}.npz").is_file():
        register(_name, f"icrsumo.learn.agent:{_cls}", description=f"learned: {_doc}")
del _name, _cls, _doc


def register_plugins(registry: AgentRegistry = REGISTRY, group: str = ENTRY_POINT_GROUP) -> None:
    """Register the agents that installed packages declare in the ``icrsumo.agents``
    entry-point group (or another ``group``: the guards'), lazily (their modules are imported
    when the entry is asked for); a name already taken or not a valid name is skipped and kept
    in ``skipped_plugins``."""
    from importlib.metadata import entry_points

    for ep in sorted(entry_points(group=group), key=lambda e: e.name):
        dist = getattr(getattr(ep, "dist", None), "name", "") or "?"
        try:
            registry.register(ep.name, f"{ep.module}:{ep.attr}", description=f"plugin ({dist})", plugin=dist)
        except (ValueError, TypeError) as err:
            registry.skipped_plugins.append((ep.name, dist, str(err)))


register_plugins()

#: the agent `icrsumo evaluate` uses when none is named (:data:`icrsumo.core.defaults.DEFAULT_AGENT`,
#: where its checkpoint ships)
DEFAULT_AGENT = _DEFAULT if _DEFAULT in REGISTRY else "instruction-follower"


@dataclass(frozen=True)
class OnDevice:
    """A factory of ``factory``'s agents on ``device`` (calls ``factory(device=device)``).
    ``name``, ``privileged``, ``needs_route`` and the rest are the factory's; ``agent_class``
    lets :func:`icrsumo.agents.base.batch_hook` find the class's ``act_batch``. Picklable when
    the factory is."""

    factory: Callable[..., Agent]
    device: str

    def __call__(self) -> Agent:
        return self.factory(device=self.device)

    @property
    def agent_class(self) -> Any:
        return self.factory

    def __getattr__(self, attr: str) -> Any:  # name, privileged, needs_route, ...
        if attr.startswith("__") or attr in ("factory", "device"):
            raise AttributeError(attr)
        return getattr(self.factory, attr)


def takes_device(factory: object) -> bool:
    """Whether ``factory`` accepts a ``device`` keyword (the learned agents do)."""
    try:
        params = inspect.signature(factory).parameters  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False
    p = params.get("device")
    return p is not None and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)


def load_class(spec: str) -> type:
    """The class of a ``module:Class`` or ``path/file.py:Class`` spec, without checking the
    protocol (``icrsumo check-agent`` reports what is missing); errors are InputErrors."""
    target, _, cls_name = spec.rpartition(":")
    if not target or not cls_name:
        raise InputError(Field("agents"), spec, "not a built-in agent nor MODULE:CLASS",
                         f"use one of {', '.join(REGISTRY)}, a module:Class, path/file.py:Class, "
                         "remote:http://HOST:PORT or llm:MODEL@http://HOST:PORT/v1")
    try:
        if target.endswith(".py"):
            path = Path(target)
            if not path.is_file():
                problem = "is a folder, not an agent file" if path.is_dir() else "agent file not found"
                raise InputError(path, "", problem, "check the path before ':'")
            name = f"{PATH_MODULE_PREFIX}{abs(hash(str(path.resolve())))}"
            mod_spec = importlib.util.spec_from_file_location(name, path)
            module = importlib.util.module_from_spec(mod_spec)
            sys.modules[name] = module
            mod_spec.loader.exec_module(module)
        else:
            module = importlib.import_module(target)
    except InputError:
        raise
    except BaseException as err:  # noqa: BLE001 - the user's module failed to import (or exited)
        raise InputError(Field("agents"), spec, f"cannot import {target} ({type(err).__name__}: {err})",
                         "make the module importable (PYTHONPATH, dependencies)") from None
    cls = getattr(module, cls_name, None)
    if cls is None:
        raise InputError(Field("agents"), spec, f"{target} has no attribute {cls_name}",
                         "check the class name")
    if not callable(cls):
        raise InputError(Field("agents"), spec, f"{target}.{cls_name} is not a class", "name the agent class")
    return cls


def _import_class(spec: str) -> type:
    cls = load_class(spec)
    cls_name = spec.rpartition(":")[2]
    missing = [m for m in ("reset", "act") if not callable(getattr(cls, m, None))]
    if missing:
        raise InputError(Field("agents"), spec, f"{cls_name} does not implement the agent protocol "
                         f"(missing {', '.join(missing)})", "add reset(info) and act(obs) -> Action")
    return cls


def agent_factory(spec: str, device: str | None = None) -> Callable[[], Agent]:
    """A zero-argument factory of fresh agents for ``spec``; errors are InputErrors. With
    ``device`` (cpu, cuda, cuda:N, auto), a factory that takes a ``device`` keyword makes its
    agents there (:class:`OnDevice`); other agents ignore it."""
    if spec in REGISTRY:
        factory: Callable[..., Agent] = REGISTRY[spec]
    elif spec.startswith(REMOTE_PREFIX):
        from .remote import remote_factory

        return remote_factory(spec[len(REMOTE_PREFIX):])
    elif spec.startswith(LLM_PREFIX):
        from .llm import llm_factory

        return llm_factory(spec)
    else:
        factory = _import_class(spec)
    if device is not None and takes_device(factory):
        return OnDevice(factory, device)
    return factory


#: prefix of the label an agent given as a Python object (class, function, instance) runs under
PYTHON_PREFIX = "python:"


@dataclass(frozen=True)
class InstanceFactory:
    """A factory of fresh copies of one agent instance (a deep copy per episode, so every
    episode starts from the instance as given). ``name``, ``privileged``, ``needs_route`` are
    the instance's; ``agent_class`` is its class. Picklable when the instance is."""

    instance: Any

    def __call__(self) -> Agent:
        import copy

        return copy.deepcopy(self.instance)

    @property
    def agent_class(self) -> Any:
        return type(self.instance)

    def __getattr__(self, attr: str) -> Any:  # name, privileged, needs_route, fingerprint, ...
        if attr.startswith("__") or attr == "instance":
            raise AttributeError(attr)
        return getattr(self.instance, attr)


@dataclass(frozen=True)
class FunctionFactory:
    """A function that makes agents, with what one agent it made tells: ``name``,
    ``agent_class``, ``privileged``, ``needs_route``. Picklable when the function is."""

    fn: Callable[[], Agent]
    name: str
    agent_class: type
    privileged: bool = False
    needs_route: bool = False

    def __call__(self) -> Agent:
        return self.fn()


def python_agent(obj: object, where: str = "agents") -> tuple[str, Callable[..., Agent]]:
    """(label, factory) of an agent given as a Python object: an agent class or a zero-argument
    function making agents (the factory), or an agent instance (copied per episode). The label
    ``python:module.Qualname`` stands for it where a spec would (an unnamed agent's results are
    stored under it). An InputError naming ``where`` for anything else."""
    if isinstance(obj, type) or (callable(obj) and not callable(getattr(obj, "act", None))):
        factory: Callable[..., Agent] = obj  # type: ignore[assignment]
        cls = obj
        if not isinstance(obj, type):  # a function: one agent made now tells its name and class
            try:
                probe = obj()
            except Exception as err:  # noqa: BLE001 - the user's function failed
                raise InputError(where, _qualname(obj), f"the agent function raised {type(err).__name__}: "
                                 f"{err}", "make it return an agent") from None
            cls = type(probe)
            factory = FunctionFactory(obj, agent_name(_qualname(obj), probe), cls,
                                      bool(getattr(probe, "privileged", False)),
                                      bool(getattr(probe, "needs_route", False)))
            if callable(getattr(probe, "close", None)):  # the probe holds nothing for the run
                with contextlib.suppress(Exception):
                    probe.close()
            del probe
        missing = [m for m in ("reset", "act") if not callable(getattr(cls, m, None))]
        if missing:
            raise InputError(where, _qualname(obj), f"does not make agents of the agent protocol (missing "
                             f"{', '.join(missing)})", "add reset(info) and act(obs) -> Action")
        return f"{PYTHON_PREFIX}{_qualname(obj)}", factory
    if callable(getattr(obj, "act", None)) and callable(getattr(obj, "reset", None)):
        return f"{PYTHON_PREFIX}{_qualname(type(obj))} instance", InstanceFactory(obj)
    raise InputError(where, repr(obj)[:60], "is not an agent", "give an agent spec (a string), an agent "
                     "class, a function that makes agents, or an agent instance (with reset and act)")


def agent_name(spec: str, agent: object) -> str:
    """The name results are stored under: the agent's (or its class's) ``name`` when it is a
    non-empty string, else the spec (a ``name`` property read on the class is no name: its text
    would change from run to run)."""
    name = getattr(agent, "name", None)
    return name if isinstance(name, str) and name.strip() else spec


def make_agent(spec: str, device: str | None = None) -> Agent:
    """A fresh instance of the agent ``spec`` (on ``device``, see :func:`agent_factory`)."""
    return agent_factory(spec, device)()
