"""Old module names kept working: issue 44 moved modules into layer folders (docs/layout.md), and
``import icrsumo.routes``, ``from icrsumo import errors`` or a string such as
``"icrsumo.env:ICRDriveEnv"`` still give the module now at its new place (the same module object,
private names included), with a :class:`DeprecationWarning` naming the new place.

:data:`MOVED` is the one table of old -> new names; :class:`MovedFinder` (installed by
``import icrsumo``) answers an import of an old name with the module at the new one. The modules
:mod:`icrsumo.compat.metrics`, :mod:`~icrsumo.compat.termination` and
:mod:`~icrsumo.compat.report` re-export the names that ``icrsumo.metrics``, ``icrsumo.termination``
and ``icrsumo.report`` had before the scoring and reporting packages took them over."""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from types import ModuleType

#: old module name -> the module that now holds it (both under ``icrsumo.``)
MOVED: dict[str, str] = {
    "agents.batched": "agents.hosting.batched",
    "agents.batching": "agents.hosting.batching",
    "agents.serve": "agents.hosting.serve",
    "agents.watch": "agents.hosting.watch",
    "aggregate": "results.aggregate",
    "api": "app.api",
    "attack": "evaluation.attack",
    "attribution": "results.attribution",
    "bundled": "evaluation.bundled",
    "cache": "evaluation.bundled",
    "check_agent": "app.check_agent",
    "cli": "app.cli.main",
    "control": "sim.control",
    "convert": "world.convert",
    "decisions": "results.decisions",
    "defaults": "core.defaults",
    "devices": "core.devices",
    "digests": "evaluation.digests",
    "doccheck": "core.doccheck",
    "dynamics": "world.dynamics",
    "env": "app.env",
    "errors": "core.errors",
    "fsio": "core.fsio",
    "guards.measure": "results.guards",
    "llmio": "core.llmio",
    "llmserver": "agents.hosting.llmserver",
    "logs": "results.logs",
    "metrics": "compat.metrics",
    "networks": "world.networks",
    "procs": "core.procs",
    "report": "compat.report",
    "resources": "core.resources",
    "routes": "world.routes",
    "routing": "world.routing",
    "scenario": "world.scenario",
    "show": "app.show",
    "store": "results.store",
    "summary": "results.summary",
    "termination": "compat.termination",
    "traffic": "world.traffic",
    "types": "core.types",
    "vocab": "core.vocab",
}


class _Alias(importlib.abc.Loader):
    """Loads an old name as the module at its new place (the import system keeps whatever the
    loader leaves in ``sys.modules`` under the old name)."""

    def __init__(self, target: str) -> None:
        self.target = target

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        return ModuleType(spec.name)

    def exec_module(self, module: ModuleType) -> None:
        warnings.warn(f"{module.__name__} moved to {self.target}; import it from there",
                      DeprecationWarning, stacklevel=2)
        sys.modules[module.__name__] = importlib.import_module(self.target)


class MovedFinder(importlib.abc.MetaPathFinder):
    """A finder for the old names in :data:`MOVED` (and nothing else)."""

    def find_spec(self, fullname: str, path: object = None, target: object = None
                  ) -> importlib.machinery.ModuleSpec | None:
        if not fullname.startswith("icrsumo."):
            return None
        new = MOVED.get(fullname[len("icrsumo."):])
        if new is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, _Alias(f"icrsumo.{new}"))


def install() -> None:
    """Put :class:`MovedFinder` on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, MovedFinder) for f in sys.meta_path):
        sys.meta_path.append(MovedFinder())
