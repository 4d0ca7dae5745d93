"""Agent specs -> agent factories: built-in names, ``module:Class`` or ``path/file.py:Class``."""

from __future__ import annotations

import importlib
import importlib.util
import sys
from collections.abc import Callable
from pathlib import Path

from ..errors import InputError
from .base import Agent
from .privileged import InstructionFollower, RouteOracle

BUILTIN: dict[str, type] = {"route-oracle": RouteOracle, "instruction-follower": InstructionFollower}
#: the agent `icrsumo evaluate` uses when none is named
DEFAULT_AGENT = "instruction-follower"


def _import_class(spec: str) -> type:
    target, _, cls_name = spec.rpartition(":")
    if not target or not cls_name:
        raise InputError("--agent", spec, "not a built-in agent nor MODULE:CLASS",
                         f"use one of {', '.join(BUILTIN)}, a module:Class or path/file.py:Class")
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
    missing = [m for m in ("reset", "act") if not callable(getattr(cls, m, None))]
    if missing:
        raise InputError("--agent", spec, f"{cls_name} does not implement the agent protocol "
                         f"(missing {', '.join(missing)})", "add reset(info) and act(obs) -> Action")
    return cls


def agent_factory(spec: str) -> Callable[[], Agent]:
    """A zero-argument factory of fresh agents for ``spec``; errors are InputErrors."""
    if spec in BUILTIN:
        return BUILTIN[spec]
    return _import_class(spec)


def agent_name(spec: str, agent: object) -> str:
    """The name results are stored under: the agent's ``name`` attribute, else the spec."""
    return str(getattr(agent, "name", "") or spec)


def make_agent(spec: str) -> Agent:
    """A fresh instance of the agent ``spec``."""
    return agent_factory(spec)()
