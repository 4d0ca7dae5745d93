"""``icrsumo serve-agent``: the reference ``icrsumo-agent/1`` server wrapping any agent spec.

One agent instance per session (``POST /reset`` makes a fresh one, so parallel episodes never
share state); every agent call runs on one worker thread, in arrival order per session.
Concurrent ``POST /act`` requests of parallel episodes are gathered into batches of up to
``max_batch``: whatever arrived while the previous batch ran. If the agent class has the
optional ``act_batch`` hook (:func:`icrsumo.agents.base.batch_hook`: a static
``act_batch(agents, observations)`` with each session's own instance, or a method
``act_batch(self, observations)`` for stateless agents), a batch is one call of it, e.g. one
torch forward pass; otherwise each session's ``act`` is called in turn. Privileged agents need
the simulator's World view, which is not sent over the network: they are refused. Binds
127.0.0.1 unless told otherwise. A hung agent call blocks the worker thread: clients then time
out with "agent did not answer within N s". Asking for clarification passes through both ways
(``info.asking`` and ``obs.answer`` to the agent, its ``action.ask`` back; optional fields,
:mod:`icrsumo.agents.remote`).
"""

from __future__ import annotations

import hmac
import json
import queue
import signal
import sys
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

from icrsumo.core.devices import check_device
from icrsumo.core.errors import Field, InputError, note

from ..identity import fingerprint
from ..registry import agent_factory, agent_name
from ..remote import PROTOCOL, ProtocolError, decode_info, decode_obs, encode_action, message, shared_key
from .batching import BatchingCore, Task

#: largest request body (bytes) the server reads
MAX_BODY = 64 << 20


class AgentServer(BatchingCore):
    """An HTTP server for agent ``spec`` on ``host:port`` (port 0: a free one, see ``.port``);
    ``device``: where a learned agent runs (cpu by default, cuda, cuda:N, auto)."""

    def __init__(self, spec: str, host: str = "127.0.0.1", port: int = 0, max_batch: int = 8,
                 max_sessions: int = 256, device: str | None = None, key: str | None = None) -> None:
        factory = agent_factory(spec, device)
        if getattr(factory, "privileged", False):
            raise InputError("serve-agent", spec, "is a privileged agent: it needs the simulator's World "
                             "view, which is not sent over the network", "serve a non-privileged agent")
        super().__init__(factory, max_batch, max_sessions, name=agent_name(spec, factory))
        self.spec = spec
        #: the shared key every request must carry (``Authorization: Bearer KEY``; None: none)
        self.key = key
        #: the served agent's identity (:mod:`icrsumo.agents.identity`), reported by ``GET /info``
        self.fingerprint = fingerprint(factory)
        self._queue: queue.Queue[Task | None] = queue.Queue()
        self._worker = threading.Thread(target=self._work, name="icrsumo-agent-worker", daemon=True)
        self._worker.start()
        server = self

        class Handler(_Handler):
            owner = server

        try:
            self.httpd = ThreadingHTTPServer((host, port), Handler)
        except (OSError, OverflowError, TypeError) as err:
            why = getattr(err, "strerror", "") or err
            raise InputError(f"{Field('host')}/{Field('port')}", f"{host}:{port}", f"cannot listen ({why})",
                             f"pick a free port or another {Field('host')}") from None
        self.httpd.daemon_threads = True
        self.host, self.port = self.httpd.server_address[:2]

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    def info(self) -> dict[str, Any]:
        return {"name": self.name, "fingerprint": self.fingerprint, "privileged": False,
                "batching": self.batch_hook, "max_batch": self.max_batch, "sessions": len(self.sessions),
                "stats": dict(self.stats)}

    def serve_forever(self) -> None:
        self.httpd.serve_forever(poll_interval=0.2)

    def start(self) -> AgentServer:
        """Serve on a background thread (for tests and notebooks)."""
        threading.Thread(target=self.serve_forever, name="icrsumo-agent-http", daemon=True).start()
        return self

    def shutdown(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
        self._queue.put(None)

    def submit(self, task: Task) -> Task:
        self._queue.put(task)
        task.done.wait()
        return task

    # ------------------------------------------------------------------ worker thread
    def _work(self) -> None:
        while True:
            first = self._queue.get()
            if first is None:
                return
            tasks = [first]
            while True:  # whatever else has arrived: one batch
                try:
                    nxt = self._queue.get_nowait()
                except queue.Empty:
                    break
                if nxt is None:
                    self._queue.put(None)
                    break
                tasks.append(nxt)
            self.run(tasks)


class _Handler(BaseHTTPRequestHandler):
    """HTTP/1.1 keep-alive handler; every answer is a protocol message."""

    protocol_version = "HTTP/1.1"
    disable_nagle_algorithm = True  # headers and body are separate writes: no 40 ms delayed-ACK stalls
    owner: AgentServer

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - quiet by default
        pass

    def _send(self, status: int, body: bytes) -> None:
        self.send_response(status)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def _error(self, status: int, text: str) -> None:
        self._send(status, message(error=text))

    def _authorized(self) -> bool:
        """Whether the request carries the server's shared key (always, without one); a 401
        protocol answer otherwise."""
        key = self.owner.key
        if key is None:
            return True
        given = self.headers.get("Authorization", "")
        if hmac.compare_digest(given.encode("utf-8", "replace"), f"Bearer {key}".encode()):
            return True
        self.close_connection = True
        self._error(401, "this server requires its shared key: use remote:http://HOST:PORT?key_env=VAR with "
                         "VAR holding the key it was started with (icrsumo serve-agent --key-env)")
        return False

    def do_GET(self) -> None:  # noqa: N802 - http.server's naming
        if not self._authorized():
            return None
        if self.path.split("?")[0] != "/info":
            return self._error(404, f"no such endpoint GET {self.path} (use GET /info)")
        self._send(200, message(**self.owner.info()))

    def do_POST(self) -> None:  # noqa: N802
        if not self._authorized():
            return None
        path = self.path.split("?")[0]
        if path not in ("/reset", "/act", "/close"):
            return self._error(404, f"no such endpoint POST {self.path} (use /reset, /act, /close)")
        try:
            length = int(self.headers.get("Content-Length", "-1"))
        except ValueError:
            length = -1
        if not 0 <= length <= MAX_BODY:
            self.close_connection = True
            return self._error(400, f"a body of 0 to {MAX_BODY} bytes with Content-Length is required")
        try:
            doc = json.loads(self.rfile.read(length), parse_constant=_no_constant)
            if not isinstance(doc, dict):
                raise ProtocolError("the body must be a JSON object")
            if doc.get("protocol") != PROTOCOL:
                raise ProtocolError(f"protocol {doc.get('protocol')!r} is not {PROTOCOL!r}")
            session = doc.get("session")
            if not isinstance(session, str) or not 1 <= len(session) <= 128:
                raise ProtocolError("session must be a string of 1 to 128 characters")
            kind = path[1:]
            payload = decode_info(doc.get("info")) if kind == "reset" else \
                decode_obs(doc.get("obs")) if kind == "act" else None
        except (ValueError, ProtocolError, OverflowError, TypeError) as err:
            return self._error(400, f"malformed request: {' '.join(str(err).split())[:200]}")
        except RecursionError:
            return self._error(400, "malformed request: JSON nested too deeply")
        task = self.owner.submit(Task(kind, session, payload))
        if task.status != 200:
            return self._error(task.status, task.error)
        if kind != "act":
            return self._send(200, message())
        try:
            body = message(action=encode_action(task.result))
        except ProtocolError as bad:
            return self._error(422, str(bad))
        self._send(200, body)


def _no_constant(name: str) -> float:
    """JSON's non-standard NaN / Infinity are refused (a request with them is malformed)."""
    raise ValueError(f"{name} is not a JSON number")


#: hosts that only this machine reaches
_LOOPBACK = ("127.0.0.1", "localhost", "::1")


def serve(spec: str, host: str = "127.0.0.1", port: int = 8765, max_batch: int = 8,
          device: str | None = None, key_env: str | None = None) -> None:
    """Serve ``spec`` (on ``device``) until interrupted (the ``icrsumo serve-agent`` command).
    ``key_env``: the environment variable holding a shared key every request must carry; a
    server on another host than the loopback without one says that it has no authentication."""
    if not isinstance(port, int) or not 0 <= port <= 65535:
        raise InputError(Field("port"), str(port), "out of range", "use 0 to 65535 (0: any free port)")
    if max_batch < 1:
        raise InputError(Field("max_batch"), str(max_batch), "must be at least 1", "give a positive count")
    if device is not None:
        check_device(device)
    key = shared_key(key_env, Field("key_env"), key_env) if key_env is not None else None
    server = AgentServer(spec, host, port, max_batch, device=device, key=key)
    if key is None and host not in _LOOPBACK and not host.startswith("127."):
        note(f"serving on {host}: every machine that can reach port {server.port} can drive this agent "
             f"and read its answers (the server has no authentication); start it with {Field('key_env')} "
             "VAR (a shared key in VAR) and give clients remote:URL?key_env=VAR", kind="warning")
    print(f"icrsumo: serving agent {server.name!r} ({spec}) on {server.url} (protocol {PROTOCOL}, "
          f"{'act_batch' if server.batch_hook else 'act per session'}, max batch {max_batch}); "
          f"Ctrl-C stops", file=sys.stderr, flush=True)
    t0 = time.perf_counter()

    def stop(signum, frame):
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, stop)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.shutdown()
        s = server.stats
        print(f"icrsumo: served {s['acts']} actions in {s['batches']} batches (largest {s['largest_batch']}) "
              f"over {s['resets']} episodes in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
