"""Batched agent calls without any transport: one agent instance per session, act batches.

:class:`BatchingCore` is the part that ``icrsumo serve-agent`` (HTTP,
:mod:`icrsumo.agents.hosting.serve`) and evaluation's batched inference processes (Unix sockets,
:mod:`icrsumo.agents.hosting.batched`) share. It takes an agent *factory* (a zero-argument callable that
makes fresh, non-privileged agents, e.g. a class) and knows nothing of specs, the registry or
the wire: callers resolve the spec and move the :class:`Task` objects.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from icrsumo.core.errors import Field, InputError, describe

from ..base import Agent, AgentError, batch_hook, validate_action

#: what a task asks for
TASK_KINDS = ("reset", "act", "close")


@dataclass
class Task:
    """One request of a session: ``kind`` (reset, act or close) with its ``payload`` (the
    EpisodeInfo of a reset, the Observation of an act). :meth:`BatchingCore.run` sets
    ``status`` (200 ok, 404 unknown session, 422 the agent broke the protocol, 500 it raised),
    ``result`` (an act's Action) or ``error`` (one line), and sets ``done``."""

    kind: str
    session: str
    payload: Any = None
    done: threading.Event = field(default_factory=threading.Event)
    result: Any = None
    status: int = 200
    error: str = ""


class BatchingCore:
    """Sessions of the agents made by ``factory`` and their act batches (``max_batch``), with
    statistics (resets, acts, batches, largest_batch). ``run(tasks)`` runs tasks that arrived
    together: resets and closes first (a session's reset always precedes its acts: its client
    waits), then the acts in batches, through the agent class's ``act_batch`` hook
    (:func:`icrsumo.agents.base.batch_hook`) when it has one. The factory must make
    non-privileged agents: the simulator's World view exists only in the episode worker.
    ``name``: the agent's name (default: the factory's ``name`` attribute)."""

    def __init__(self, factory: Callable[[], Agent], max_batch: int = 8, max_sessions: int = 256,
                 name: str | None = None) -> None:
        if max_batch < 1:
            raise InputError(Field("max_batch"), str(max_batch), "must be at least 1",
                             "give a positive count")
        self.factory = factory
        self.name = name or str(getattr(factory, "name", "") or getattr(factory, "__name__", "agent"))
        self.batch = batch_hook(factory)
        self.batch_hook = self.batch is not None
        self.max_batch, self.max_sessions = max_batch, max_sessions
        self.sessions: OrderedDict[str, Any] = OrderedDict()
        self.stats = {"resets": 0, "acts": 0, "batches": 0, "largest_batch": 0}

    def run(self, tasks: list[Task]) -> None:
        """Run ``tasks`` (each gets ``status``, ``result`` / ``error`` and is marked done)."""
        acts = [t for t in tasks if t.kind == "act"]
        for t in tasks:
            if t.kind != "act":
                self._run_other(t)
        for i in range(0, len(acts), self.max_batch):
            self._run_acts(acts[i:i + self.max_batch])

    def _run_other(self, t: Task) -> None:
        try:
            if t.kind == "reset":
                agent = self.factory()
                agent.reset(t.payload)
                self.sessions[t.session] = agent
                self.sessions.move_to_end(t.session)
                while len(self.sessions) > self.max_sessions:  # forget the least recently used
                    self.sessions.popitem(last=False)
                self.stats["resets"] += 1
            else:
                agent = self.sessions.pop(t.session, None)
                if agent is not None and callable(getattr(agent, "close", None)):
                    agent.close()
            t.result = None
        except (Exception, SystemExit, KeyboardInterrupt) as err:  # the user's agent failed (or exited)
            t.status, t.error = 500, f"{t.kind}() raised {describe(err)}"
        t.done.set()

    def _run_acts(self, batch: list[Task]) -> None:
        live = []
        for t in batch:
            agent = self.sessions.get(t.session)
            if agent is None:
                t.status, t.error = 404, (f"unknown session {t.session!r}: POST /reset first (the server "
                                          f"may have restarted or dropped the session)")
                t.done.set()
            else:
                self.sessions.move_to_end(t.session)
                live.append((t, agent))
        if not live:
            return
        self.stats["batches"] += 1
        self.stats["acts"] += len(live)
        self.stats["largest_batch"] = max(self.stats["largest_batch"], len(live))
        if self.batch_hook and len(live) > 1:
            try:
                actions = self.batch([a for _, a in live], [t.payload for t, _ in live])
                if not isinstance(actions, (list, tuple)) or len(actions) != len(live):
                    raise AgentError(f"act_batch() returned {type(actions).__name__} of "
                                     f"{len(actions) if hasattr(actions, '__len__') else '?'} actions "
                                     f"for {len(live)} observations")
                results = [(a, None) for a in actions]
            except (Exception, SystemExit, KeyboardInterrupt) as err:
                results = [(None, err)] * len(live)
        else:
            results = []
            for t, agent in live:
                try:
                    results.append((agent.act(t.payload), None))
                except (Exception, SystemExit, KeyboardInterrupt) as err:
                    results.append((None, err))
        for (t, _), (action, err) in zip(live, results):
            if err is None:
                try:
                    t.result = validate_action(action)
                except AgentError as bad:
                    t.status, t.error = 422, str(bad)
            elif isinstance(err, AgentError):
                t.status, t.error = 422, str(err)
            else:
                t.status, t.error = 500, f"act() raised {describe(err)}"
            t.done.set()
