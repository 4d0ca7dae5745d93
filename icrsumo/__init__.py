"""icrsumo: instruction-robustness evaluation of language-conditioned driving agents on SUMO.

The Python API (:mod:`icrsumo.app.api`) is exported here and imported on first use, so that
``import icrsumo`` stays light: ``icrsumo.evaluate(...)``, ``icrsumo.load_suite(...)``,
``icrsumo.run_episode(...)``, ``icrsumo.digest(out)``, ``icrsumo.compare_digests(out, other)``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from icrsumo.compat import install as _install_moved

__version__ = "0.1.0"

#: public name -> the module that defines it (imported on first access)
_LAZY = {
    "evaluate": "icrsumo.app.api",
    "load_suite": "icrsumo.app.api",
    "Suite": "icrsumo.app.api",
    "EvalResult": "icrsumo.evaluation.run",
    "run_episode": "icrsumo.app.api",
    "digest": "icrsumo.app.api",
    "compare_digests": "icrsumo.app.api",
}

__all__ = ["EvalResult", "Suite", "__version__", "compare_digests", "digest", "evaluate", "load_suite",
           "run_episode"]

if TYPE_CHECKING:
    from icrsumo.app.api import Suite, compare_digests, digest, evaluate, load_suite, run_episode
    from icrsumo.evaluation.run import EvalResult


_install_moved()  # old module names (icrsumo.routes, ...) keep importing: icrsumo.compat


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'icrsumo' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later accesses skip this function
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})
