"""Agent names -> agent instances (built-in agents; users' classes arrive with `evaluate`)."""

from __future__ import annotations

from ..errors import InputError
from .base import Agent
from .privileged import InstructionFollower, RouteOracle

BUILTIN: dict[str, type] = {"route-oracle": RouteOracle, "instruction-follower": InstructionFollower}


def make_agent(name: str) -> Agent:
    """A fresh instance of the built-in agent ``name``."""
    if name not in BUILTIN:
        raise InputError("--agent", name, "unknown agent", f"use one of {', '.join(BUILTIN)}")
    return BUILTIN[name]()
