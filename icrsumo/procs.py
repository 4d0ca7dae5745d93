"""Child processes that must not outlive the process that started them (pool workers, the
batched-inference process)."""

from __future__ import annotations

import os
import signal
import sys
import threading
import time


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
