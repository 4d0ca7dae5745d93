"""How an agent's calls (and an instruction guard's) are guarded against hanging: one
:class:`CallWatch` protocol, given explicitly to whoever calls the agent (an evaluation's episode
worker, ``check-agent``). ``who`` names the caller in a timeout: ``"agent"``, or ``"guard NAME"``
for a guard's ``reset`` / ``check`` (:class:`~icrsumo.guards.base.GuardTimeout`).

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

from ..base import AgentTimeout

#: the caller of an agent's own calls
AGENT = "agent"


def timeout_message(timeout: float, who: str = AGENT) -> str:
    """The words of every agent-call (or guard-call: ``who``) timeout."""
    return f"{who} did not answer within {timeout:g} s"


def timeout_error(timeout: float, who: str = AGENT) -> AgentTimeout:
    """The exception of a call of ``who`` that overran ``timeout`` s: an
    :class:`AgentTimeout`, a :class:`~icrsumo.guards.base.GuardTimeout` for a guard's."""
    from icrsumo.guards.base import GuardTimeout

    return (AgentTimeout if who == AGENT else GuardTimeout)(timeout_message(timeout, who))


class CallWatch(Protocol):
    """Runs one call ``fn(arg)`` of ``who`` under a time limit."""

    def call(self, fn: Callable[[Any], Any], arg: Any, who: str = AGENT) -> Any: ...


class Unwatched:
    """Calls without a limit."""

    def call(self, fn: Callable[[Any], Any], arg: Any, who: str = AGENT) -> Any:
        return fn(arg)


class SlotWatch:
    """Marks ``time.monotonic()`` in ``slot`` (a shared double, 0.0: no call) while a call runs,
    and in ``caller`` (a shared int, optional) whether it is the agent's (0) or its guard's (1);
    the parent enforces the limit (:func:`overran`) and names the caller (:func:`overran_by`)."""

    def __init__(self, slot: Any, caller: Any = None) -> None:
        self.slot, self.caller = slot, caller

    def call(self, fn: Callable[[Any], Any], arg: Any, who: str = AGENT) -> Any:
        if self.caller is not None:
            self.caller.value = 0 if who == AGENT else 1
        self.slot.value = time.monotonic()
        try:
            return fn(arg)
        finally:
            self.slot.value = 0.0


def overran_by(caller: Any, guard: str) -> str:
    """``who`` of the call a :class:`SlotWatch` marked in ``caller``: the agent, or ``guard``."""
    return f"guard {guard}" if caller is not None and caller.value == 1 and guard else AGENT


def overran(slot: Any, timeout: float, now: float) -> bool:
    """Whether the call marked in ``slot`` (by a :class:`SlotWatch`) has run over ``timeout`` s."""
    began = slot.value
    return bool(began) and now - began > timeout


class AlarmWatch:
    """Interrupts a call with :class:`AgentTimeout` after ``timeout`` s (SIGALRM; None: no
    limit). Works in the main thread of a process only; elsewhere calls are unwatched."""

    def __init__(self, timeout: float | None) -> None:
        self.timeout = timeout

    def call(self, fn: Callable[[Any], Any], arg: Any, who: str = AGENT) -> Any:
        timeout = self.timeout
        if timeout is None or not hasattr(signal, "SIGALRM") \
                or threading.current_thread() is not threading.main_thread():
            return fn(arg)

        def expired(signum, frame):
            raise timeout_error(timeout, who)

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
