"""How an agent's calls are guarded against hanging: one :class:`CallWatch` protocol, given
explicitly to whoever calls the agent (an evaluation's episode worker, ``check-agent``).

* :class:`Unwatched`: no limit (``--agent-timeout 0``, or one in-process worker without one);
* :class:`SlotWatch`: a local pool worker marks when its current call began in a shared slot;
  the parent process reads the slots (:func:`overran`) and kills and replaces a worker whose
  call overruns (this stops any hang, also in C code);
* :class:`AlarmWatch`: where no parent watches (Ray workers), SIGALRM interrupts a call after
  ``timeout`` s with :class:`~icrsumo.agents.base.AgentTimeout` (hangs in Python code; main
  thread only, elsewhere the call is unwatched);
* :class:`ThreadWatch`: ``check-agent`` runs every call on one helper thread and gives up on a
  call after ``timeout`` s with :class:`~icrsumo.agents.base.AgentTimeout` (the hung call keeps
  that thread; SUMO stays on the caller's).
"""

from __future__ import annotations

import queue
import signal
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol

from .base import AgentTimeout


def timeout_message(timeout: float) -> str:
    """The words of every agent-call timeout."""
    return f"agent did not answer within {timeout:g} s"


class CallWatch(Protocol):
    """Runs one agent call ``fn(arg)`` under a time limit."""

    def call(self, fn: Callable[[Any], Any], arg: Any) -> Any: ...


class Unwatched:
    """Calls without a limit."""

    def call(self, fn: Callable[[Any], Any], arg: Any) -> Any:
        return fn(arg)


class SlotWatch:
    """Marks ``time.monotonic()`` in ``slot`` (a shared double, 0.0: no call) while a call runs;
    the parent enforces the limit (:func:`overran`)."""

    def __init__(self, slot: Any) -> None:
        self.slot = slot

    def call(self, fn: Callable[[Any], Any], arg: Any) -> Any:
        self.slot.value = time.monotonic()
        try:
            return fn(arg)
        finally:
            self.slot.value = 0.0


def overran(slot: Any, timeout: float, now: float) -> bool:
    """Whether the call marked in ``slot`` (by a :class:`SlotWatch`) has run over ``timeout`` s."""
    began = slot.value
    return bool(began) and now - began > timeout


class AlarmWatch:
    """Interrupts a call with :class:`AgentTimeout` after ``timeout`` s (SIGALRM; None: no
    limit). Works in the main thread of a process only; elsewhere calls are unwatched."""

    def __init__(self, timeout: float | None) -> None:
        self.timeout = timeout

    def call(self, fn: Callable[[Any], Any], arg: Any) -> Any:
        timeout = self.timeout
        if timeout is None or not hasattr(signal, "SIGALRM") \
                or threading.current_thread() is not threading.main_thread():
            return fn(arg)

        def expired(signum, frame):
            raise AgentTimeout(timeout_message(timeout))

        old = signal.signal(signal.SIGALRM, expired)
        signal.setitimer(signal.ITIMER_REAL, timeout)
        try:
            return fn(arg)
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
            signal.signal(signal.SIGALRM, old)


class ThreadWatch:
    """Runs calls on one daemon thread; a call that has not returned after ``timeout`` s raises
    :class:`AgentTimeout` (the call keeps running on that thread, which is abandoned). The
    call's own exception is re-raised; ``last_s`` is the duration (s) of the last finished call."""

    def __init__(self, timeout: float) -> None:
        self.timeout = timeout
        self.last_s = 0.0
        self._in: queue.Queue = queue.Queue()
        threading.Thread(target=self._loop, name="icrsumo-agent-call", daemon=True).start()

    def _loop(self) -> None:
        while True:
            fn, args, box, done = self._in.get()
            t0 = time.perf_counter()
            try:
                box["value"] = fn(*args)
            except BaseException as err:  # handed to the caller
                box["error"] = err
            box["dt"] = time.perf_counter() - t0
            done.set()

    def call(self, fn: Callable[..., Any], *args: Any) -> Any:
        box: dict[str, Any] = {}
        done = threading.Event()
        self._in.put((fn, args, box, done))
        if not done.wait(self.timeout):
            raise AgentTimeout(timeout_message(self.timeout))
        self.last_s = box["dt"]
        if "error" in box:
            raise box["error"]
        return box.get("value")
