"""The agent registry and agent specs.

An agent is named by a *spec*: a registered name (the built-ins: ``route-oracle``,
``instruction-follower`` and the learned agents whose checkpoints ship), ``module:Class``,
``path/file.py:Class`` or ``remote:http://HOST:PORT``. :func:`agent_factory` turns a spec into
a zero-argument factory of fresh agents (InputErrors for bad specs).

Names are registered explicitly with :func:`register`, which refuses a name that is already
taken (as Gymnasium's environment registry and waymax's metric registry do)::

    from icrsumo.agents.registry import register
    register("my-agent", MyAgent, description="drives from the BEV raster")

A factory with a ``device`` keyword (the learned agents: ``LearnedAgent(checkpoint,
device="cpu")``) is built on another device with ``agent_factory(spec, device="cuda")``.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import sys
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..defaults import DEFAULT_AGENT as _DEFAULT
from ..errors import InputError
from ..learn.agent import CHECKPOINTS, NgramAgent, NgramAugAgent, TokenAgent
from .base import Agent
from .privileged import InstructionFollower, RouteOracle

#: ``remote:http://HOST:PORT``: an agent behind an icrsumo-agent/1 server (icrsumo.agents.remote)
REMOTE_PREFIX = "remote:"


@dataclass(frozen=True)
class AgentEntry:
    """A registered agent: its ``name`` (the spec), its ``factory`` (a zero-argument callable,
    usually the agent class) and a one-line ``description``."""

    name: str
    factory: Callable[..., Agent]
    description: str = ""


class AgentRegistry(Mapping[str, Callable[..., Agent]]):
    """Registered agent names -> their factories (read-only as a mapping; change it with
    :meth:`register` and :meth:`unregister`)."""

    def __init__(self) -> None:
        self._entries: dict[str, AgentEntry] = {}

    def register(self, name: str, factory: Callable[..., Agent], *, description: str = "") -> AgentEntry:
        """Register ``factory`` under ``name``; a ValueError when the name is taken or not a
        valid spec (empty, with whitespace, or with ``:``, which marks module:Class and remote
        specs), a TypeError when ``factory`` is not callable."""
        if not isinstance(name, str) or not name or ":" in name or any(c.isspace() for c in name):
            raise ValueError(f"agent name {name!r} is not valid: use a non-empty name without ':' or "
                             f"whitespace, e.g. 'my-agent'")
        if not callable(factory):
            raise TypeError(f"cannot register agent {name!r}: its factory {factory!r} is not callable "
                            f"(pass the agent class or a zero-argument function)")
        old = self._entries.get(name)
        if old is not None:
            raise ValueError(f"agent {name!r} is already registered (by {_qualname(old.factory)}): pick "
                             f"another name, or unregister({name!r}) first")
        entry = self._entries[name] = AgentEntry(name, factory, description)
        return entry

    def unregister(self, name: str) -> AgentEntry:
        """Remove ``name`` (KeyError naming the registered ones when it is not registered)."""
        try:
            return self._entries.pop(name)
        except KeyError:
            raise KeyError(f"agent {name!r} is not registered (registered: {', '.join(self)})") from None

    def entry(self, name: str) -> AgentEntry:
        return self._entries[name]

    def __getitem__(self, name: str) -> Callable[..., Agent]:
        return self._entries[name].factory

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)


def _qualname(obj: object) -> str:
    return f"{getattr(obj, '__module__', '?')}.{getattr(obj, '__qualname__', type(obj).__name__)}"


#: the process's agent registry
REGISTRY = AgentRegistry()
register = REGISTRY.register
unregister = REGISTRY.unregister
#: registered name -> factory (the registry as a read-only mapping; the name older callers use)
BUILTIN: Mapping[str, Callable[..., Agent]] = REGISTRY

register("route-oracle", RouteOracle,
         description="privileged: follows the scenario's route (an upper reference)")
register("instruction-follower", InstructionFollower,
         description="privileged: follows the instructions as a careful driver would")
# learned agents whose checkpoints ship with the package (torch loads on first use)
for _cls in (TokenAgent, NgramAgent, NgramAugAgent):
    if (CHECKPOINTS / _cls.checkpoint).is_file():
        _doc = (_cls.__doc__ or "").strip().splitlines()[0].removeprefix(f"``{_cls.name}``: ")
        register(_cls.name, _cls, description=f"learned: {_doc.replace('``', '')}")
del _cls, _doc

#: the agent `icrsumo evaluate` uses when none is named (:data:`icrsumo.defaults.DEFAULT_AGENT`,
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
        raise InputError("--agent", spec, "not a built-in agent nor MODULE:CLASS",
                         f"use one of {', '.join(REGISTRY)}, a module:Class, path/file.py:Class or "
                         "remote:http://HOST:PORT")
    try:
        if target.endswith(".py"):
            path = Path(target)
            if not path.is_file():
                problem = "is a folder, not an agent file" if path.is_dir() else "agent file not found"
                raise InputError(path, "", problem, "check the path before ':'")
            name = f"icrsumo_user_agent_{abs(hash(str(path.resolve())))}"
            mod_spec = importlib.util.spec_from_file_location(name, path)
            module = importlib.util.module_from_spec(mod_spec)
            sys.modules[name] = module
            mod_spec.loader.exec_module(module)
        else:
            module = importlib.import_module(target)
    except InputError:
        raise
    except BaseException as err:  # noqa: BLE001 - the user's module failed to import (or exited)
        raise InputError("--agent", spec, f"cannot import {target} ({type(err).__name__}: {err})",
                         "make the module importable (PYTHONPATH, dependencies)") from None
    cls = getattr(module, cls_name, None)
    if cls is None:
        raise InputError("--agent", spec, f"{target} has no attribute {cls_name}", "check the class name")
    if not callable(cls):
        raise InputError("--agent", spec, f"{target}.{cls_name} is not a class", "name the agent class")
    return cls


def _import_class(spec: str) -> type:
    cls = load_class(spec)
    cls_name = spec.rpartition(":")[2]
    missing = [m for m in ("reset", "act") if not callable(getattr(cls, m, None))]
    if missing:
        raise InputError("--agent", spec, f"{cls_name} does not implement the agent protocol "
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
