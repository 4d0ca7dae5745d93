"""Remote agents: the ``icrsumo-agent/1`` protocol (HTTP/1.1 + JSON) and its client.

An agent runs in its own process or on another machine behind an HTTP server (the reference
server is ``icrsumo serve-agent``, :mod:`icrsumo.agents.hosting.serve`); ``--agent
remote:http://HOST:PORT`` drives it. Every body is a JSON object carrying
``"protocol": "icrsumo-agent/1"``; arrays travel as ``{"dtype", "shape", "data"}`` with
``data`` the base64 of the zlib-compressed little-endian C-order bytes.

=====================  ==========================================  ==================================
request                body                                        answer (200)
=====================  ==========================================  ==================================
``GET /info``          —                                           ``name``, ``fingerprint`` (what the
                                                                   agent is: ``sha256:`` + 64 hex digits,
                                                                   optional), ``privileged`` (false),
                                                                   ``batching``, ``max_batch``, ``stats``
``POST /reset``        ``session`` (client-chosen id), ``info``     ``{}``: a fresh agent instance for
                       (EpisodeInfo fields)                        the session, reset with ``info``
``POST /act``          ``session``, ``obs``: ``t``, ``bev``         ``action``: ``{"control": {"steer",
                       (array), ``speed``, ``compass``,             "throttle", "brake"}}`` or
                       ``instruction``, ``instruction_id``,        ``{"waypoints": array,
                       ``notice``
                                                                   "target_speed": number | null}``
``POST /close``        ``session``                                 ``{}``: the session's agent is dropped
=====================  ==========================================  ==================================

Asking for clarification travels as three optional booleans, sent only when true, so that
messages without them are those of before and either side may be older: ``info.asking`` (the
navigator answers asks in this episode), ``obs.answer`` (the instruction is the navigator's
answer) and ``action.ask`` (the agent asks). A peer that does not know them ignores them (an
agent behind an older server never asks; an older client never answers). ``obs.compass`` (the
ego's heading in radians, :attr:`icrsumo.agents.base.Observation.compass`) is sent by every
client since issue 47; an older client's observations read it as 0.

Any other status carries ``{"error": "..."}`` in plain words (400 malformed request, 404
unknown path or session, 422 the agent's action broke the protocol, 500 the agent raised). The
client turns every failure into one line: :class:`AgentTimeout` ("agent did not answer within
N s") when the server is slower than the per-request timeout (a deadline for the whole request,
however slowly the answer trickles in), :class:`AgentError` when the server is down, answers
with an error or with malformed data; an unreachable server at planning time is an
:class:`icrsumo.core.errors.InputError` (exit status 2). The shared key (``?key_env=VAR``) or a
password in the URL (sent as HTTP Basic) goes to that server only (redirects are not followed)
and is redacted from what the server sends back; the URL is shown without its password.
"""

from __future__ import annotations

import base64
import contextlib
import http.client
import json
import os
import socket
import time
import uuid
import zlib
from dataclasses import asdict
from typing import Any
from urllib.parse import parse_qs, urlsplit

import numpy as np

from icrsumo.core.errors import Field, InputError, check_key_env, check_key_text, display_url
from icrsumo.core.llmio import authorization, redact, secrets_of
from icrsumo.world.dynamics import Control

from .base import Action, AgentError, AgentTimeout, EpisodeInfo, Observation

PROTOCOL = "icrsumo-agent/1"
#: seconds a request may take before the client gives up (``?timeout=S`` in the URL overrides)
DEFAULT_TIMEOUT = 60.0
#: dtypes an array may have on the wire
DTYPES = ("uint8", "int8", "int16", "int32", "int64", "float32", "float64", "bool")
#: largest decompressed array (bytes) a peer accepts
MAX_ARRAY_BYTES = 64 << 20


class ProtocolError(ValueError):
    """A message that does not follow ``icrsumo-agent/1`` (what is wrong, in plain words)."""


# --------------------------------------------------------------------------- codec
def encode_array(a: np.ndarray) -> dict[str, Any]:
    """An array as ``{"dtype", "shape", "data"}`` (zlib level 1, base64)."""
    a = np.asarray(a)
    if a.dtype.name not in DTYPES:
        raise ProtocolError(f"arrays of dtype {a.dtype} cannot be sent (use one of {', '.join(DTYPES)})")
    raw = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<")).tobytes()
    return {"dtype": a.dtype.name, "shape": list(a.shape),
            "data": base64.b64encode(zlib.compress(raw, 1)).decode("ascii")}


def decode_array(d: Any, what: str) -> np.ndarray:
    """The array of :func:`encode_array`'s dict; ProtocolError naming ``what`` when malformed."""
    if not isinstance(d, dict) or set(d) < {"dtype", "shape", "data"}:
        raise ProtocolError(f"{what} must be an object with dtype, shape and data")
    dtype, shape, data = d["dtype"], d["shape"], d["data"]
    if dtype not in DTYPES:
        raise ProtocolError(f"{what}: unsupported dtype {dtype!r}")
    if not isinstance(shape, list) or not all(isinstance(n, int) and n >= 0 for n in shape):
        raise ProtocolError(f"{what}: shape must be a list of non-negative integers")
    if not isinstance(data, str):
        raise ProtocolError(f"{what}: data must be a base64 string")
    try:
        packed = base64.b64decode(data, validate=True)
        dec = zlib.decompressobj()
        raw = dec.decompress(packed, MAX_ARRAY_BYTES + 1)
    except (ValueError, zlib.error) as err:
        raise ProtocolError(f"{what}: data is not base64 of zlib-compressed bytes ({err})") from None
    dt = np.dtype(dtype).newbyteorder("<")
    n = int(np.prod(shape)) if shape else 1
    if len(raw) != n * dt.itemsize or not dec.eof:
        raise ProtocolError(f"{what}: {len(raw)} bytes do not match dtype {dtype} and shape {shape}")
    return np.frombuffer(raw, dtype=dt).reshape(shape).astype(np.dtype(dtype), copy=True)


def _number(v: Any, what: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ProtocolError(f"{what} must be a number, got {type(v).__name__}")
    return float(v)


def _string(v: Any, what: str) -> str:
    if not isinstance(v, str):
        raise ProtocolError(f"{what} must be a string, got {type(v).__name__}")
    return v


def _flag(d: dict, key: str, what: str) -> bool:
    """The optional boolean ``d[key]`` (false when absent); ProtocolError naming ``what``."""
    v = d.get(key, False)
    if not isinstance(v, bool):
        raise ProtocolError(f"{what} must be true or false, got {type(v).__name__}")
    return v


def encode_info(info: EpisodeInfo) -> dict[str, Any]:
    d = asdict(info)
    if not d["asking"]:
        del d["asking"]   # sent only when true: the message of a run without asking is unchanged
    return d


def decode_info(d: Any) -> EpisodeInfo:
    if not isinstance(d, dict):
        raise ProtocolError("info must be an object")
    try:
        return EpisodeInfo(route_id=_string(d["route_id"], "info.route_id"),
                           town=_string(d["town"], "info.town"),
                           net=_string(d["net"], "info.net"),
                           step_length=_number(d["step_length"], "info.step_length"),
                           control_dt=_number(d["control_dt"], "info.control_dt"),
                           seed=int(_number(d["seed"], "info.seed")),
                           asking=_flag(d, "asking", "info.asking"))
    except KeyError as err:
        raise ProtocolError(f"info lacks {err.args[0]}") from None


def encode_obs(obs: Observation) -> dict[str, Any]:
    return {"t": float(obs.t), "bev": encode_array(obs.bev), "speed": float(obs.speed),
            "compass": float(obs.compass),
            "instruction": obs.instruction, "instruction_id": int(obs.instruction_id), "notice": obs.notice,
            **({"answer": True} if obs.answer else {})}


def decode_obs(d: Any) -> Observation:
    if not isinstance(d, dict):
        raise ProtocolError("obs must be an object")
    try:
        iid = d["instruction_id"]
        if isinstance(iid, bool) or not isinstance(iid, int):
            raise ProtocolError("obs.instruction_id must be an integer")
        return Observation(t=_number(d["t"], "obs.t"), bev=decode_array(d["bev"], "obs.bev"),
                           speed=_number(d["speed"], "obs.speed"),
                           compass=_number(d.get("compass", 0.0), "obs.compass"),
                           instruction=_string(d["instruction"], "obs.instruction"), instruction_id=iid,
                           notice=_string(d["notice"], "obs.notice"), answer=_flag(d, "answer", "obs.answer"))
    except KeyError as err:
        raise ProtocolError(f"obs lacks {err.args[0]}") from None


def encode_action(action: Action) -> dict[str, Any]:
    """A validated action on the wire (``ask`` only when true)."""
    ask = {"ask": True} if action.ask else {}
    if action.control is not None:
        c = action.control
        return {"control": {"steer": float(c.steer), "throttle": float(c.throttle), "brake": float(c.brake)},
                **ask}
    ts = action.target_speed
    return {"waypoints": encode_array(np.asarray(action.waypoints)),
            "target_speed": None if ts is None else float(ts), **ask}


def decode_action(d: Any) -> Action:
    if not isinstance(d, dict) or ("control" in d) == ("waypoints" in d):
        raise ProtocolError("action must be an object with exactly one of control or waypoints")
    ask = _flag(d, "ask", "action.ask")
    if "control" in d:
        c = d["control"]
        if not isinstance(c, dict):
            raise ProtocolError("action.control must be an object")
        try:
            return Action(control=Control(steer=_number(c["steer"], "control.steer"),
                                          throttle=_number(c["throttle"], "control.throttle"),
                                          brake=_number(c["brake"], "control.brake")), ask=ask)
        except KeyError as err:
            raise ProtocolError(f"action.control lacks {err.args[0]}") from None
    ts = d.get("target_speed")
    return Action(waypoints=decode_array(d["waypoints"], "action.waypoints"),
                  target_speed=None if ts is None else _number(ts, "action.target_speed"), ask=ask)


def message(**fields: Any) -> bytes:
    """A protocol message body."""
    return json.dumps({"protocol": PROTOCOL, **fields}, allow_nan=False).encode("utf-8")


# --------------------------------------------------------------------------- client
def parse_url(url: str) -> tuple[str, int, float, str | None]:
    """(host, port, timeout s, shared key) of ``http://HOST:PORT[?timeout=S&key_env=VAR]``
    (the key read from the environment variable VAR, for a server started with ``--key-env``);
    InputError when malformed or when VAR is not set."""
    parts = urlsplit(url)
    fix = "use remote:http://HOST:PORT, e.g. remote:http://127.0.0.1:8765 (?timeout=S&key_env=VAR optional)"
    if parts.scheme != "http" or not parts.hostname:
        raise InputError(Field("agents"), f"remote:{url}", "not an http://HOST:PORT address", fix)
    query = parse_qs(parts.query)
    try:
        port = parts.port or 80
        timeout = float(query.get("timeout", [DEFAULT_TIMEOUT])[0])
    except ValueError:
        raise InputError(Field("agents"), f"remote:{url}", "bad port or timeout", fix) from None
    if not 0 < timeout < float("inf"):
        raise InputError(Field("agents"), f"remote:{url}", "timeout must be a positive number of seconds",
                         fix)
    key = None
    if "key_env" in query:
        key = shared_key(query["key_env"][0], Field("agents"), f"remote:{url}")
    return parts.hostname, port, timeout, key


def shared_key(var: str, option: Field, value: str) -> str:
    """The shared key held by the environment variable ``var``; an InputError naming ``option``
    when ``var`` is no variable name or is not set (the key itself never goes on a command line)."""
    key = os.environ.get(check_key_env(var, option, value), "").strip()
    if not key:
        raise InputError(option, value, f"the shared key variable {var} is not set",
                         f"export {var}=... (the same key on both sides) before starting")
    return check_key_text(key, var, option, value)


class _DeadlineSocket(socket.socket):
    """A socket whose every send and receive gets only the time left until ``deadline`` (a
    ``time.monotonic()`` instant; TimeoutError once it has passed), so a whole request ends by
    then however slowly the answer trickles in (no watchdog thread on the per-step path)."""

    deadline = float("inf")

    def _time_left(self) -> None:
        left = self.deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError("timed out")
        self.settimeout(left)

    def recv_into(self, *args: Any) -> int:
        self._time_left()
        return super().recv_into(*args)

    def sendall(self, *args: Any) -> None:
        self._time_left()
        super().sendall(*args)


def _deadline_socket(address: tuple[str, int], timeout: float, *args: Any) -> _DeadlineSocket:
    """``socket.create_connection``, as a :class:`_DeadlineSocket`."""
    sock = socket.create_connection(address, timeout, *args)
    return _DeadlineSocket(sock.family, sock.type, sock.proto, sock.detach())


class _Connection:
    """One keep-alive HTTP/1.1 connection; every failure becomes an AgentError / AgentTimeout.
    Each request has ``timeout`` s in all; the credentials (the shared ``key``, else the URL's
    password) go to this host only and are redacted from the server's answers."""

    def __init__(self, url: str, host: str, port: int, timeout: float, key: str | None = None) -> None:
        self.url, self.host, self.port, self.timeout = url, host, port, timeout
        self.auth = authorization(url, key)
        self.secrets = secrets_of(url, key)
        self.conn: http.client.HTTPConnection | None = None

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
            self.conn = None

    def _exchange(self, method: str, path: str, body: bytes | None) -> tuple[int, bytes]:
        """(status, body) of one request, all of it within ``timeout`` s (TimeoutError past it)."""
        deadline = time.monotonic() + self.timeout
        if self.conn is None:
            self.conn = http.client.HTTPConnection(self.host, self.port, timeout=self.timeout)
            self.conn._create_connection = _deadline_socket   # type: ignore[attr-defined]
            self.conn.connect()
            self.conn.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.conn.sock.deadline = deadline
        headers = {"Content-Type": "application/json"} if body is not None else {}
        if self.auth is not None:
            headers["Authorization"] = self.auth
        self.conn.request(method, path, body=body, headers=headers)
        resp = self.conn.getresponse()
        return resp.status, redact(resp.read(), self.secrets)

    def request(self, method: str, path: str, body: bytes | None = None) -> dict[str, Any]:
        where = f"remote agent at {display_url(self.url)}"
        try:
            status, raw = self._exchange(method, path, body)
        except TimeoutError:
            self.close()
            raise AgentTimeout(f"agent did not answer within {self.timeout:g} s ({where}, {path})") from None
        except ConnectionRefusedError:
            self.close()
            raise AgentError(f"{where} is not reachable (connection refused): is icrsumo serve-agent "
                             f"running there?") from None
        except (OSError, http.client.HTTPException) as err:
            self.close()
            raise AgentError(f"{where}: connection failed ({type(err).__name__}: "
                             f"{redact(str(err), self.secrets)})") from None
        if 300 <= status < 400:
            raise AgentError(f"{where} answered HTTP {status}, a redirect, which is not followed "
                             "(credentials go to the URL's own server only): give the server's own address")
        try:
            doc = json.loads(raw)
        except ValueError:
            raise AgentError(f"{where} answered malformed data: not JSON (HTTP {status}, "
                             f"{raw[:60]!r})") from None
        if not isinstance(doc, dict):
            raise AgentError(f"{where} answered malformed data: not a JSON object")
        if status != 200:
            error = redact(str(doc.get("error") or ""), self.secrets)
            raise AgentError(f"{where}: {error or f'HTTP {status}'}")
        if doc.get("protocol") != PROTOCOL:
            raise AgentError(f"{where} answered malformed data: protocol {doc.get('protocol')!r}, "
                             f"expected {PROTOCOL!r}")
        return doc


class RemoteAgent:
    """An agent behind an ``icrsumo-agent/1`` server. One session per episode: ``reset``
    opens it (a fresh agent instance on the server), ``close`` ends it."""

    privileged = False

    def __init__(self, url: str, name: str, timeout: float = DEFAULT_TIMEOUT) -> None:
        host, port, _, key = parse_url(url)
        self.url, self.name = url, name
        self._conn = _Connection(url, host, port, timeout, key)
        self.session: str | None = None

    def reset(self, info: EpisodeInfo) -> None:
        self.close()
        session = uuid.uuid4().hex  # an id only: no effect on any result
        self._conn.request("POST", "/reset", message(session=session, info=encode_info(info)))
        self.session = session

    def act(self, obs: Observation) -> Action:
        if self.session is None:
            raise AgentError("act() before reset()")
        doc = self._conn.request("POST", "/act", message(session=self.session, obs=encode_obs(obs)))
        try:
            return decode_action(doc.get("action"))
        except ProtocolError as err:
            raise AgentError(f"remote agent at {display_url(self.url)} answered malformed data: "
                             f"{redact(str(err), self._conn.secrets)}") from None

    def close(self) -> None:
        """End the session on the server (best effort) and the connection."""
        if self.session is not None:
            session, self.session = self.session, None
            with contextlib.suppress(AgentError):
                self._conn.request("POST", "/close", message(session=session))
        self._conn.close()


class RemoteFactory:
    """``agent_factory`` of ``remote:URL``: asks ``GET /info`` once (name, protocol) and makes
    a :class:`RemoteAgent` per episode. The server must be up: InputError otherwise."""

    privileged = False

    def __init__(self, url: str) -> None:
        host, port, timeout, key = parse_url(url)
        self.url, self.timeout = url, timeout
        conn = _Connection(url, host, port, min(timeout, 10.0), key)
        try:
            info = conn.request("GET", "/info")
        except AgentError as err:
            raise InputError(Field("agents"), f"remote:{url}", str(err),
                             "start it with icrsumo serve-agent SPEC --port N, or fix the address") from None
        finally:
            conn.close()
        name = info.get("name")
        if not isinstance(name, str) or not name:
            raise InputError(Field("agents"), f"remote:{url}", "GET /info answered no agent name",
                             "serve the agent with icrsumo serve-agent")
        self.name = name
        self.info = info
        fp = info.get("fingerprint")
        #: the server's own account of its agent (``GET /info``'s ``fingerprint``); a server that
        #: gives none is known by its agent's name and address only
        self.fingerprint = fp if isinstance(fp, str) and fp.strip() else \
            f"remote {name} at {display_url(url)}"

    def __call__(self) -> RemoteAgent:
        return RemoteAgent(self.url, self.name, self.timeout)


def remote_factory(url: str) -> RemoteFactory:
    """The factory of ``remote:URL`` agents (URL: ``http://HOST:PORT[?timeout=S]``)."""
    return RemoteFactory(url)


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on ``host`` right now (for tests and examples)."""
    with socket.socket() as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])
