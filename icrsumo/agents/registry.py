"""Agent specs -> agent factories: built-in names, ``module:Class``, ``path/file.py:Class`` or
``remote:http://HOST:PORT``."""

from __future__ import annotations

import importlib
import importlib.util
import sys
from collections.abc import Callable
from pathlib import Path

from ..errors import InputError
from ..learn.agent import CHECKPOINTS, NgramAgent, NgramAugAgent, TokenAgent
from .base import Agent
from .privileged import InstructionFollower, RouteOracle

BUILTIN: dict[str, type] = {"route-oracle": RouteOracle, "instruction-follower": InstructionFollower}
# learned agents whose checkpoints ship with the package (torch loads on first use)
BUILTIN.update({cls.name: cls for cls in (TokenAgent, NgramAgent, NgramAugAgent)
                if (CHECKPOINTS / cls.checkpoint).is_file()})
#: the agent `icrsumo evaluate` uses when none is named: the shipped learned agent with the
#: best baseline DS on the tiny suite (96.2 against 89.6 and 88.3: README, Learned agents)
DEFAULT_AGENT = "bev-token" if "bev-token" in BUILTIN else "instruction-follower"
#: ``remote:http://HOST:PORT``: an agent behind an icrsumo-agent/1 server (icrsumo.agents.remote)
REMOTE_PREFIX = "remote:"
#: ``batched:SOCKET#NAME``: set by ``evaluate --batch-inference`` for its workers (icrsumo.agents.batched)
BATCHED_PREFIX = "batched:"


def load_class(spec: str) -> type:
    """The class of a ``module:Class`` or ``path/file.py:Class`` spec, without checking the
    protocol (``icrsumo check-agent`` reports what is missing); errors are InputErrors."""
    target, _, cls_name = spec.rpartition(":")
    if not target or not cls_name:
        raise InputError("--agent", spec, "not a built-in agent nor MODULE:CLASS",
                         f"use one of {', '.join(BUILTIN)}, a module:Class, path/file.py:Class or "
                         "remote:http://HOST:PORT")
    try:
        if target.endswith(".py"):
            path = Path(target)
            if not path.is_file():
                raise InputError(path, "", "agent file not found", "check the path before ':'")
            name = f"icrsumo_user_agent_{abs(hash(str(path.resolve())))}"
            mod_spec = importlib.util.spec_from_file_location(name, path)
            module = importlib.util.module_from_spec(mod_spec)
            sys.modules[name] = module
            mod_spec.loader.exec_module(module)
        else:
            module = importlib.import_module(target)
    except InputError:
        raise
    except Exception as err:  # the user's module failed to import
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


def agent_factory(spec: str) -> Callable[[], Agent]:
    """A zero-argument factory of fresh agents for ``spec``; errors are InputErrors."""
    if spec in BUILTIN:
        return BUILTIN[spec]
    if spec.startswith(REMOTE_PREFIX):
        from .remote import remote_factory

        return remote_factory(spec[len(REMOTE_PREFIX):])
    if spec.startswith(BATCHED_PREFIX):  # internal: an episode worker of --batch-inference
        from .batched import BatchedFactory

        return BatchedFactory(spec[len(BATCHED_PREFIX):])
    return _import_class(spec)


def agent_name(spec: str, agent: object) -> str:
    """The name results are stored under: the agent's ``name`` attribute, else the spec."""
    return str(getattr(agent, "name", "") or spec)


def make_agent(spec: str) -> Agent:
    """A fresh instance of the agent ``spec``."""
    return agent_factory(spec)()
