"""Guard names -> guard classes: the built-in ``text`` and ``plan`` guards, ``llm:MODEL@URL``,
and those installed packages declare in the ``icrsumo.guards`` entry-point group
(``[project.entry-points."icrsumo.guards"] NAME = "module:Class"``). Entries are imported when
first asked for; a name is registered once (duplicates are refused)."""

from __future__ import annotations

from collections.abc import Callable

from icrsumo.agents.registry import AgentRegistry, register_plugins
from icrsumo.core.errors import Field, InputError

from .base import Guard, guarded_name

__all__ = ["GUARDS", "GuardRegistry", "guard_factory", "guard_name", "guarded_name"]

#: the entry-point group through which installed packages add guards
GUARD_ENTRY_POINTS = "icrsumo.guards"
#: ``llm:MODEL@http://HOST:PORT/v1``: the language-model guard (icrsumo.guards.llm)
LLM_GUARD_PREFIX = "llm:"


class GuardRegistry(AgentRegistry):
    """Registered guard names -> their classes (see :class:`icrsumo.agents.registry.AgentRegistry`)."""

    kind = "guard"
    option = Field("guards")


#: the process's guard registry
GUARDS = GuardRegistry()
GUARDS.register("text", "icrsumo.guards.text:TextGuard",
                description="from the text alone: authority framing, retractions, unplaceable intents")
GUARDS.register("plan", "icrsumo.guards.plan:PlanGuard",
                description="checks the instruction's intent against the navigation plan")
GUARDS.register("text-learned", "icrsumo.learn.text_guard:LearnedTextGuard",
                description="from the text alone: a linear classifier over hashed character n-grams "
                            "and word pairs")
register_plugins(GUARDS, GUARD_ENTRY_POINTS)


def guard_factory(spec: str) -> Callable[[], Guard]:
    """A zero-argument factory of fresh guards for ``spec`` (a registered name or
    ``llm:MODEL@URL``); an InputError for an unknown name, before any episode runs."""
    if not isinstance(spec, str) or not spec:
        raise InputError(Field("guards"), repr(spec), "not a guard name", f"use one of {', '.join(GUARDS)}")
    if spec.startswith(LLM_GUARD_PREFIX):
        from .llm import llm_guard_factory

        return llm_guard_factory(spec)
    if spec not in GUARDS:
        raise InputError(Field("guards"), spec, "unknown guard",
                         f"use one of {', '.join(GUARDS)}, llm:MODEL@URL, or install a plugin that adds it")
    return GUARDS[spec]


def guard_name(spec: str, factory: Callable[[], Guard]) -> str:
    """The name a guard's rows carry (``AGENT+guard:NAME``): its class's ``name`` when that is a
    non-empty string without whitespace, else the spec."""
    name = getattr(factory, "name", None)
    return name if isinstance(name, str) and name and not any(c.isspace() for c in name) else spec


