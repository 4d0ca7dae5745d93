"""Child processes that must not outlive the process that started them (pool workers, the
batched-inference process)."""

from __future__ import annotations

import contextlib
import multiprocessing.context
import os
import signal
import sys
import threading
import time
import types
from collections.abc import Iterator


def die_with_parent(parent: int) -> None:
    """Make this (child) process die when its parent does: Linux's ``PR_SET_PDEATHSIG``
    (SIGKILL), and an exit at once if ``parent`` is already gone; elsewhere a daemon thread that
    exits the process once its parent pid changes."""
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
        else:
            if os.getppid() != parent:
                os._exit(1)
            return

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="icrsumo-parent-watch").start()


@contextlib.contextmanager
def _script_hidden() -> Iterator[None]:
    """While a child is spawned, ``__main__`` is an empty module: the child then does not run
    the parent's script again (a script calling :func:`icrsumo.evaluate` without an
    ``if __name__ == "__main__":`` guard would start a second run in every worker)."""
    main = sys.modules.get("__main__")
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        yield
    finally:
        if main is not None:
            sys.modules["__main__"] = main


class _ScriptFreeProcess(multiprocessing.context.SpawnProcess):
    def start(self) -> None:
        with _script_hidden():
            super().start()


class _ScriptFreeContext(multiprocessing.context.SpawnContext):
    Process = _ScriptFreeProcess


_SPAWN = _ScriptFreeContext()


def spawn_context() -> multiprocessing.context.SpawnContext:
    """The ``spawn`` start method for icrsumo's own process pools (conversion, generation,
    training, batched inference), with one difference: the children do not import the parent's
    ``__main__`` script, so the Python API works from a plain script with no
    ``if __name__ == "__main__":`` guard. Their targets and arguments must therefore be
    importable from icrsumo or other modules (never objects defined in the script)."""
    return _SPAWN
