"""Batched inference inside ``icrsumo evaluate --batch-inference DEVICE``: the simulator
workers send their observations to one inference process that runs the agent's network for
all of them in one forward pass.

:func:`start_server` starts the inference process (``spawn``) for one agent spec; it builds
its agents on ``device`` (``agent_factory(spec, device)``: a learned agent's constructor
argument). It listens on a Unix socket (on Linux in the abstract namespace: no file, so a killed
run leaves nothing behind; elsewhere in a private folder, mode 0700) and accepts only clients
that know its random key (``multiprocessing.connection``'s HMAC handshake). Its loop is
single-threaded: it waits until some workers' requests are ready, reads them all, runs them
with :class:`icrsumo.agents.hosting.batching.BatchingCore` (one agent instance per episode, acts in
batches of up to ``max_batch`` through the agent's ``act_batch`` hook) and answers. No request
waits for a batch to fill: a batch is whatever arrived while the previous one ran.

``processes`` > 1 starts several such processes per agent (:func:`start_group`); each worker
uses one. The episode workers get a :class:`BatchedFactory` (the sockets, the agent's name and
the key: a picklable object that travels inside the evaluation's jobs) that makes a
:class:`BatchedAgent` per episode: one episode session, over one connection per worker process
(state of the factory). Observations and actions travel pickled, raw (no compression): a BEV
frame is 7 x 128 x 128 bytes. The inference processes are the only ones that load the network,
so the workers' cores are left to SUMO and the episode loop.

Results on CPU are those of the in-process agent, bit for bit (a learned agent runs a CPU
batch sample by sample). On a GPU they differ from CPU inference by float rounding, and the
learned agents pad every batch to a fixed size so that an episode's actions do not depend on
which other episodes share its batch (:class:`icrsumo.learn.nets.policy.Policy`).
"""

from __future__ import annotations

import contextlib
import itertools
import multiprocessing
import os
import secrets
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from multiprocessing.connection import Client, Connection, Listener, wait
from pathlib import Path
from typing import Any

from icrsumo.core.errors import Field, InputError, describe
from icrsumo.core.procs import die_with_parent, spawn_context

from ..base import AgentError, EpisodeInfo, Observation
from ..registry import agent_factory, agent_name
from .batching import TASK_KINDS, BatchingCore, Task

#: s to wait for an inference process to load its agent and listen
START_TIMEOUT = 180.0


@dataclass
class BatchServer:
    """The parent's handle of one inference process."""

    name: str
    address: str
    key: bytes = field(repr=False)
    proc: Any
    control: Connection
    folder: tempfile.TemporaryDirectory | None
    stats: dict = field(default_factory=dict)

    def stop(self) -> dict:
        """Stop the process; returns its statistics: resets, acts, batches, largest_batch and
        the seconds it spent waiting for requests, reading and answering them, and running
        the agent (wait_s, io_s, run_s)."""
        with contextlib.suppress(OSError, EOFError, BrokenPipeError):
            self.control.send("stop")
            if self.control.poll(30):
                kind, payload = self.control.recv()
                if kind == "stats":
                    self.stats = payload
        self.proc.join(timeout=30)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()
        self.control.close()
        if self.folder is not None:
            self.folder.cleanup()
        return self.stats


@dataclass
class ServerGroup:
    """Several inference processes of one agent: each episode worker uses one of them (by
    process id), so that request handling, which is Python work, runs on several cores."""

    name: str
    servers: list[BatchServer]

    def factory(self) -> BatchedFactory:
        """The picklable agent factory the episode workers use."""
        return BatchedFactory([s.address for s in self.servers], self.name, self.servers[0].key)

    def stop(self) -> dict:
        """Stop every process; returns their statistics added up (largest_batch: the largest;
        processes: their number)."""
        parts = [s.stop() for s in self.servers]
        total: dict = {}
        for part in parts:
            for key, value in part.items():
                total[key] = max(total.get(key, 0), value) if key == "largest_batch" else \
                    total.get(key, 0) + value
        if total:
            total["processes"] = len(parts)
        return total


def start_group(spec: str, device: str, max_batch: int = 32, processes: int = 1,
                factory: Callable | None = None) -> ServerGroup:
    """``processes`` inference processes of agent ``spec`` sharing one key (see
    :func:`start_server`)."""
    key = secrets.token_bytes(32)
    servers: list[BatchServer] = []
    try:
        for _ in range(processes):
            servers.append(start_server(spec, device, max_batch, key=key, factory=factory))
    except BaseException:
        for server in servers:
            server.stop()
        raise
    return ServerGroup(servers[0].name, servers)


def start_server(spec: str, device: str, max_batch: int = 32, key: bytes | None = None,
                 factory: Callable | None = None) -> BatchServer:
    """Start the inference process of agent ``spec`` on ``device`` (cpu, cuda, cuda:N, auto)
    and wait until it listens. ``key``: the clients' key (default: a fresh random one);
    ``factory``: the spec's factory when the caller has resolved it already. Errors (a
    privileged agent, no CUDA, ...) are InputErrors."""
    factory = factory if factory is not None else agent_factory(spec)
    if getattr(factory, "privileged", False):
        raise InputError(Field("batch_inference"), spec, "is a privileged agent: it needs the simulator's "
                         "World view, which only the episode worker has",
                         f"leave out {Field('batch_inference')}")
    name = agent_name(spec, factory)
    key = key if key is not None else secrets.token_bytes(32)
    address, folder = _socket_address()
    ctx = spawn_context()
    control, child = ctx.Pipe()
    proc = ctx.Process(target=_serve, args=(spec, address, key, device, max_batch, child, os.getpid()),
                       name=f"icrsumo-batch-{name}", daemon=True)
    proc.start()
    child.close()
    status, payload = ("error", f"did not start within {START_TIMEOUT:g} s")
    if control.poll(START_TIMEOUT):
        with contextlib.suppress(EOFError):
            status, payload = control.recv()
    if status != "ready":
        proc.kill()
        proc.join()
        control.close()
        if folder is not None:
            folder.cleanup()
        raise InputError(Field("batch_inference"), device,
                         f"the inference process of {spec} failed: {payload}",
                         f"pick a device this machine has (cpu, cuda), or leave out "
                         f"{Field('batch_inference')}")
    return BatchServer(name, address, key, proc, control, folder)


def _socket_address() -> tuple[str, tempfile.TemporaryDirectory | None]:
    """A fresh Unix socket address: on Linux an abstract one (no file to leave behind when the
    run is killed; the key guards it), elsewhere ``agent.sock`` in a new private folder (which
    is returned, for its removal)."""
    if sys.platform.startswith("linux"):
        return "\0icrsumo-batch-" + secrets.token_hex(16), None
    folder = tempfile.TemporaryDirectory(prefix="icrsumo-batch-")  # mode 0700
    return str(Path(folder.name) / "agent.sock"), folder


def _serve(spec: str, address: str, key: bytes, device: str, max_batch: int, control: Connection,
           parent: int | None = None) -> None:
    """The inference process: load the agent, listen, answer batches until told to stop; it
    dies with the evaluating process (``parent``), however that ends."""
    if parent is not None:
        die_with_parent(parent)
    try:
        if device.startswith("cuda"):
            import torch

            if not torch.cuda.is_available():
                raise RuntimeError("CUDA is not available on this machine")
        factory = agent_factory(spec, device)
        core = BatchingCore(factory, max_batch, name=agent_name(spec, factory))
        listener = Listener(address, family="AF_UNIX", authkey=key)
    except Exception as err:  # reported to the parent as one line
        control.send(("error", describe(err)))
        return
    pending: list[Connection] = []
    lock = threading.Lock()

    def accept() -> None:
        while True:
            try:
                conn = listener.accept()
            except (OSError, EOFError, multiprocessing.AuthenticationError):
                continue
            with lock:
                pending.append(conn)

    threading.Thread(target=accept, name="icrsumo-batch-accept", daemon=True).start()
    control.send(("ready", core.name))
    conns: list[Connection] = []
    times = {"wait_s": 0.0, "io_s": 0.0, "run_s": 0.0}
    while True:
        with lock:
            conns.extend(pending)
            pending.clear()
        t0 = time.perf_counter()
        ready = wait([control, *conns], timeout=0.05)
        t1 = time.perf_counter()
        times["wait_s"] += t1 - t0
        if control in ready:
            with contextlib.suppress(EOFError, OSError):
                control.recv()
            with contextlib.suppress(OSError):
                control.send(("stats", {**core.stats, **{k: round(v, 3) for k, v in times.items()}}))
            return
        tasks: list[tuple[Connection, Task]] = []
        for conn in ready:
            try:
                kind, session, payload = conn.recv()
            except (EOFError, OSError, ValueError, TypeError):  # a worker ended, or sent garbage
                conns.remove(conn)
                conn.close()
                continue
            task = Task(str(kind), str(session), payload)
            if kind not in TASK_KINDS:
                task.status, task.error = 400, f"unknown request {kind!r} (use {', '.join(TASK_KINDS)})"
            tasks.append((conn, task))
        t2 = time.perf_counter()
        core.run([t for _, t in tasks if t.status == 200])
        t3 = time.perf_counter()
        for conn, t in tasks:
            try:
                conn.send((t.status, t.result, t.error))
            except OSError:  # the worker was killed meanwhile (e.g. its agent call timed out)
                if conn in conns:
                    conns.remove(conn)
        times["run_s"] += t3 - t2
        times["io_s"] += time.perf_counter() - t3 + t2 - t1


# --------------------------------------------------------------------------- worker side
class BatchedFactory:
    """The agent factory of an episode worker under ``--batch-inference``: makes a
    :class:`BatchedAgent` per episode. A worker process always uses the same inference process
    (its process id modulo their number) over one connection, kept here (state of this object,
    never pickled: each process opens its own). Picklable; equal factories (same addresses,
    name and key) are interchangeable."""

    privileged = False

    def __init__(self, addresses: Sequence[str], name: str, key: bytes) -> None:
        self.addresses, self.name, self.key = tuple(addresses), name, bytes(key)
        self._conns: dict[str, Connection] = {}
        self._pid = os.getpid()
        self._ids = itertools.count()

    def __call__(self) -> BatchedAgent:
        return BatchedAgent(self, self.addresses[os.getpid() % len(self.addresses)])

    def _ident(self) -> tuple:
        return (self.addresses, self.name, self.key)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, BatchedFactory) and self._ident() == other._ident()

    def __hash__(self) -> int:
        return hash(self._ident())

    def __repr__(self) -> str:
        return f"BatchedFactory({list(self.addresses)!r}, {self.name!r})"

    def __getstate__(self) -> dict:
        return {"addresses": self.addresses, "name": self.name, "key": self.key}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["addresses"], state["name"], state["key"])

    def session_id(self) -> str:
        """A fresh session id (an id only: no effect on any result)."""
        return f"{os.getpid()}-{next(self._ids)}-{time.monotonic_ns()}"

    def connection(self, address: str) -> Connection:
        """This process's connection to the inference process at ``address``."""
        if self._pid != os.getpid():  # inherited through a fork: not ours to use
            self._conns, self._pid = {}, os.getpid()
        conn = self._conns.get(address)
        if conn is None:
            conn = self._conns[address] = Client(address, family="AF_UNIX", authkey=self.key)
        return conn

    def drop(self, address: str) -> None:
        """Forget a broken connection (the next call reconnects)."""
        conn = self._conns.pop(address, None)
        if conn is not None:
            with contextlib.suppress(OSError):
                conn.close()

    def close(self) -> None:
        """Close this process's connections."""
        for address in list(self._conns):
            self.drop(address)


class BatchedAgent:
    """An episode's agent in an episode worker: its calls go to the inference process."""

    privileged = False

    def __init__(self, factory: BatchedFactory, address: str) -> None:
        self.factory, self.address, self.name = factory, address, factory.name
        self.session: str | None = None

    def _call(self, kind: str, session: str, payload: Any) -> Any:
        try:
            conn = self.factory.connection(self.address)
            conn.send((kind, session, payload))
            status, result, error = conn.recv()
        except (OSError, EOFError, multiprocessing.AuthenticationError) as err:
            self.factory.drop(self.address)
            raise AgentError(f"the batched inference process of {self.name} is not answering "
                             f"({type(err).__name__}: {err})") from None
        if status != 200:
            raise AgentError(error)
        return result

    def reset(self, info: EpisodeInfo) -> None:
        self.close()
        session = self.factory.session_id()
        self._call("reset", session, info)
        self.session = session

    def act(self, obs: Observation) -> Any:
        if self.session is None:
            raise AgentError("act() before reset()")
        return self._call("act", self.session, obs)

    def close(self) -> None:
        """End the episode's session (best effort)."""
        if self.session is not None:
            session, self.session = self.session, None
            with contextlib.suppress(AgentError):
                self._call("close", session, None)
