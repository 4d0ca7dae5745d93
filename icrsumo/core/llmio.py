"""Talking to an OpenAI-compatible chat-completions server (vLLM, llama.cpp's server, a hosted
API): canonical request bytes and their SHA-256 (the cache key), one HTTP exchange under a total
deadline with a one-line reason for every failure, the answer text of a response body, the
models a server serves, and a content-addressed response cache on disk.

Credentials (an API key, a password in the URL) go to the URL's own origin only: a redirect to
another origin is refused. Everything a server sends back passes through :func:`redact`, which
removes them, before anyone stores, logs, caches or prints it.

Used by the LLM instruction generator (:mod:`icrsumo.instructions.llm`) and the LLM
instruction interpreter (:mod:`icrsumo.agents.llm`). Standard library only.
"""

from __future__ import annotations

import base64
import contextlib
import hashlib
import http.client
import ipaddress
import json
import os
import socket
import threading
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from .errors import display_url
from .fsio import dumps_json, write_atomic

#: larger HTTP bodies are rejected (bytes)
MAX_RESPONSE_BYTES = 8 << 20
#: the format tag of a response-cache file
CACHE_FORMAT = "icrsumo-llm-cache/1"


def canonical(body: dict) -> bytes:
    """Canonical JSON bytes of a request body (the bytes sent and hashed)."""
    return json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=False).encode("utf-8")


def request_hash(body: dict) -> str:
    """SHA-256 (hex) of :func:`canonical` ``body``: the request's cache key."""
    return hashlib.sha256(canonical(body)).hexdigest()


class Transport(Exception):
    """A failed exchange. ``unreachable``: nothing answered at all (refused, unknown host)."""

    def __init__(self, message: str, unreachable: bool = False) -> None:
        super().__init__(message)
        self.unreachable = unreachable


class TooLarge(Transport):
    """The server's answer was larger than the limit."""


class ServerFault(Transport):
    """The server answered, but not as an OpenAI-compatible server does (an HTML page, a body
    without ``choices``): a fault of the server or of its URL, never the model's answer."""


def chat_url(endpoint: str) -> str:
    """``{endpoint}/chat/completions`` (an endpoint that already ends so is kept)."""
    base = endpoint.strip().rstrip("/")
    return base if base.endswith("/chat/completions") else base + "/chat/completions"


def models_url(endpoint: str) -> str:
    """``{endpoint}/models``: the OpenAI API's list of served models."""
    base = endpoint.strip().rstrip("/").removesuffix("/chat/completions")
    return base + "/models"


def is_http(url: str) -> bool:
    parts = urllib.parse.urlsplit(url)
    return parts.scheme in ("http", "https") and bool(parts.hostname)


def is_loopback(url: str) -> bool:
    host = urllib.parse.urlsplit(url).hostname or ""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


# --------------------------------------------------------------------------- credentials
def origin(url: str) -> tuple[str, str, int | None]:
    """(scheme, host, port) of ``url``, the port made explicit: where credentials may go."""
    parts = urllib.parse.urlsplit(url)
    try:
        port = parts.port
    except ValueError:
        port = None
    default = {"http": 80, "https": 443}.get(parts.scheme.lower())
    return parts.scheme.lower(), (parts.hostname or "").lower(), port or default


def without_userinfo(url: str) -> str:
    """``url`` without ``user:password@`` (what is requested; the password goes in a header)."""
    parts = urllib.parse.urlsplit(url)
    netloc = parts.netloc.rpartition("@")[2]
    return urllib.parse.urlunsplit((parts.scheme, netloc, parts.path, parts.query, parts.fragment))


def authorization(url: str, api_key: str | None) -> str | None:
    """The ``Authorization`` header for ``url``: ``Bearer`` the API key, else ``Basic`` the
    URL's ``user:password``, else None."""
    if api_key:
        return f"Bearer {api_key}"
    parts = urllib.parse.urlsplit(url)
    if parts.password is None:
        return None
    pair = f"{urllib.parse.unquote(parts.username or '')}:{urllib.parse.unquote(parts.password)}"
    return "Basic " + base64.b64encode(pair.encode("utf-8")).decode("ascii")


def secrets_of(url: str, api_key: str | None) -> tuple[str, ...]:
    """Every form in which the credentials of a request to ``url`` may come back: the API key,
    the URL's password (as written and decoded), the ``Authorization`` header's token, each
    also as JSON and URL quoting write it; longest first."""
    raw = [api_key or "", urllib.parse.urlsplit(url).password or ""]
    raw.append(urllib.parse.unquote(raw[1]))
    header = authorization(url, api_key)
    raw.append(header.partition(" ")[2] if header else "")
    forms = {f for s in raw if s.strip()
             for f in (s, json.dumps(s)[1:-1], json.dumps(s)[1:-1].replace("/", "\\/"),
                       urllib.parse.quote(s, safe=""), urllib.parse.quote_plus(s))}
    return tuple(sorted(forms, key=len, reverse=True))


_T = TypeVar("_T", str, bytes)


def redact(text: _T, secrets: Iterable[str]) -> _T:
    """``text`` (str or bytes) with every secret in ``secrets`` replaced by ``***``: what a
    server sent back, made safe to store, log, cache or print."""
    as_bytes = isinstance(text, bytes)
    for s in secrets:
        if s:
            text = text.replace(s.encode("utf-8"), b"***") if as_bytes else text.replace(s, "***")
    return text


# --------------------------------------------------------------------------- the exchange
@dataclass(frozen=True)
class Reply:
    """What a server answered: the HTTP ``status``, the ``body`` (credentials already
    redacted), its ``content_type`` (media type, lower case; "" when none) and the ``secrets``
    to redact from any text taken out of it."""

    status: int
    body: bytes
    content_type: str
    secrets: tuple[str, ...] = field(default=(), repr=False)

    def clean(self, text: str) -> str:
        """``text`` taken out of the body (decoded), with the credentials redacted."""
        return redact(text, self.secrets)

    def snippet(self, n: int = 80) -> str:
        """The body's first ``n`` characters on one line (what came back, for a message)."""
        text = self.clean(self.body[: 4 * n].decode("utf-8", "replace"))
        text = " ".join("".join(c if c.isprintable() else " " for c in text).split())
        return text[:n] + ("..." if len(text) > n else "")

    def fault(self, what: str) -> ServerFault:
        """The :class:`ServerFault` of this reply, saying ``what`` is missing."""
        kind = self.content_type or "no content type"
        return ServerFault(f"answered HTTP {self.status} with {kind} ({self.snippet()!r}), not an "
                           f"OpenAI-compatible JSON answer ({what})")


class Deadline:
    """A total deadline for one request: when ``seconds`` have passed, the connections it
    watches are shut down, so a server that trickles its answer cannot hold a read past it."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.expired = False
        self._socks: list[socket.socket] = []
        self._lock = threading.Lock()
        self._timer = threading.Timer(seconds, self._expire)
        self._timer.daemon = True

    def __enter__(self) -> Deadline:
        self._timer.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._timer.cancel()

    def watch(self, sock: socket.socket) -> None:
        """Shut ``sock`` down at the deadline (at once when it has passed)."""
        with self._lock:
            self._socks.append(sock)
            if self.expired:
                _shut(sock)

    def _expire(self) -> None:
        with self._lock:
            self.expired = True
            for sock in self._socks:
                _shut(sock)


def _shut(sock: socket.socket) -> None:
    with contextlib.suppress(OSError):
        sock.shutdown(socket.SHUT_RDWR)


class _Watched:
    """A connection whose socket its :class:`Deadline` watches once connected."""

    def __init__(self, *args: Any, deadline: Deadline, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self.deadline = deadline

    def connect(self) -> None:
        super().connect()
        self.deadline.watch(self.sock)


class _HTTPConnection(_Watched, http.client.HTTPConnection):
    pass


class _HTTPSConnection(_Watched, http.client.HTTPSConnection):
    pass


class _HTTPHandler(urllib.request.HTTPHandler):
    def __init__(self, deadline: Deadline) -> None:
        super().__init__()
        self.deadline = deadline

    def http_open(self, req: urllib.request.Request) -> Any:
        return self.do_open(_HTTPConnection, req, deadline=self.deadline)


class _HTTPSHandler(urllib.request.HTTPSHandler):
    def __init__(self, deadline: Deadline) -> None:
        super().__init__()
        self.deadline = deadline

    def https_open(self, req: urllib.request.Request) -> Any:
        return self.do_open(_HTTPSConnection, req, context=self._context, deadline=self.deadline)


class _SameOrigin(urllib.request.HTTPRedirectHandler):
    """Follows a redirect within the request's origin only; one to another origin (where the
    credentials would go) is a :class:`Transport` failure."""

    def redirect_request(self, req: urllib.request.Request, fp: Any, code: int, msg: str, headers: Any,
                         newurl: str) -> urllib.request.Request | None:
        if origin(newurl) != origin(req.full_url):
            fp.close()
            raise Transport(f"redirected (HTTP {code}) to another origin, {display_url(newurl)}: credentials "
                            "are only sent to the URL's own origin, so give the server's own URL")
        return super().redirect_request(req, fp, code, msg, headers, newurl)


def _read_bounded(resp: Any, limit: int) -> bytes:
    chunks: list[bytes] = []
    size = 0
    while True:
        chunk = resp.read(65536)
        if not chunk:
            return b"".join(chunks)
        size += len(chunk)
        if size > limit:
            raise TooLarge(f"response larger than {limit} bytes")
        chunks.append(chunk)


def _reason(err: BaseException) -> tuple[str, bool]:
    """A short reason for a transport failure, and whether the endpoint was unreachable."""
    if isinstance(err, urllib.error.URLError) and isinstance(err.reason, BaseException):
        err = err.reason
    if isinstance(err, ConnectionRefusedError):
        return "connection refused", True
    if isinstance(err, socket.gaierror):
        return f"host name not resolved: {err}", True
    if isinstance(err, (TimeoutError, socket.timeout)):
        return "timed out", False
    if isinstance(err, urllib.error.URLError):
        return f"{err.reason}", False
    return f"{type(err).__name__}: {err}", False


def _open(req: urllib.request.Request, deadline: Deadline, limit: int) -> tuple[int, bytes, str]:
    """(status, body, content type) of ``req``, every step within ``deadline``."""
    proxies = [urllib.request.ProxyHandler({})] if is_loopback(req.full_url) else []
    opener = urllib.request.build_opener(*proxies, _HTTPHandler(deadline), _HTTPSHandler(deadline),
                                         _SameOrigin())
    try:
        with opener.open(req, timeout=deadline.seconds) as resp:
            return resp.status, _read_bounded(resp, limit), resp.headers.get_content_type()
    except urllib.error.HTTPError as err:
        try:
            raw = _read_bounded(err, limit)
        except (OSError, http.client.HTTPException, Transport):
            raw = b""
        finally:
            err.close()
        return err.code, raw, err.headers.get_content_type() if err.headers else ""


def exchange(url: str, data: bytes | None, *, api_key: str | None, timeout: float,
             limit: int = MAX_RESPONSE_BYTES) -> Reply:
    """POST ``data`` (GET when None) to ``url``: the server's :class:`Reply`, the whole exchange
    (connect, headers, body) within ``timeout`` s and the body at most ``limit`` bytes.
    ``api_key`` goes as ``Authorization: Bearer``, else a password in the URL as ``Basic``; a
    redirect to another origin is refused. Transport failures raise :class:`Transport`
    (:class:`TooLarge` for an oversized body), their reason redacted. A loopback server is
    reached directly, whatever ``*_proxy`` variables say."""
    secrets = secrets_of(url, api_key)
    target = without_userinfo(url)
    headers = {"Accept": "application/json"}
    if data is not None:
        headers["Content-Type"] = "application/json"
    auth = authorization(url, api_key)
    if auth:
        headers["Authorization"] = auth
    req = urllib.request.Request(target, data=data, headers=headers, method="GET" if data is None else "POST")
    deadline = Deadline(timeout)
    try:
        with deadline:
            status, raw, kind = _open(req, deadline, limit)
    except Transport as err:
        raise type(err)(redact(str(err), secrets), err.unreachable) from None
    except (urllib.error.URLError, http.client.HTTPException, OSError, ValueError) as err:
        reason, unreachable = _reason(err)
        if deadline.expired:
            reason, unreachable = "timed out", False
        raise Transport(redact(reason, secrets), unreachable=unreachable) from None
    if deadline.expired:   # the body may have been cut at the deadline
        raise Transport("timed out")
    return Reply(status, redact(raw, secrets), kind, secrets)


def http_problem(reply: Reply) -> str:
    """``HTTP 404: model not found``: a status and the error message of its body, one line."""
    detail = reply.body[:300].decode("utf-8", "replace")
    try:
        err = json.loads(reply.body)
        if isinstance(err, dict):
            inner = err.get("error", err.get("detail", err))
            detail = str(inner.get("message", inner) if isinstance(inner, dict) else inner)[:300]
    except (ValueError, RecursionError):
        pass
    detail = " ".join(reply.clean(detail).split())
    return f"HTTP {reply.status}" + (f": {detail}" if detail else "")


class Invalid(Exception):
    """An answer that breaks the protocol; ``problems`` lists what is wrong."""

    def __init__(self, problems: list[str]) -> None:
        super().__init__("; ".join(problems))
        self.problems = problems

    @property
    def summary(self) -> str:
        shown = "; ".join(self.problems[:3])
        more = len(self.problems) - 3
        return shown + (f" (and {more} more problem(s))" if more > 0 else "")


def answer_text(reply: Reply) -> tuple[str, str]:
    """(``choices[0].message.content``, ``choices[0].finish_reason`` or "") of a
    chat-completions response: the model's answer text ("" when it said nothing), redacted.
    :class:`ServerFault` when the body is not such a response (an HTML page, no choices)."""
    try:
        body = json.loads(reply.body)
    except (ValueError, RecursionError):
        raise reply.fault("the body is not JSON") from None
    choices = body.get("choices") if isinstance(body, dict) else None
    if not isinstance(choices, list) or not choices or not isinstance(choices[0], dict):
        raise reply.fault("no choices[0]")
    message = choices[0].get("message")
    content = message.get("content") if isinstance(message, dict) else False
    if content is not None and not isinstance(content, str):
        raise reply.fault("no choices[0].message.content text")
    reason = choices[0].get("finish_reason")
    return reply.clean(content or ""), reason if isinstance(reason, str) else ""


def served_models(endpoint: str, *, api_key: str | None, timeout: float) -> list[str] | None:
    """The model ids ``GET {endpoint}/models`` lists, or None when the server has no such list
    (an answer other than 200). :class:`Transport` when unreachable or refusing the key,
    :class:`ServerFault` when a 200 is not the OpenAI API's list (``data: [{"id": ...}]``)."""
    reply = exchange(models_url(endpoint), None, api_key=api_key, timeout=timeout, limit=1 << 20)
    if reply.status in (401, 403):
        raise Transport(http_problem(reply))
    if reply.status != 200:
        return None
    try:
        data = json.loads(reply.body).get("data")
        return [reply.clean(str(m["id"])) for m in data if isinstance(m, dict) and "id" in m]
    except (ValueError, RecursionError, AttributeError, TypeError):
        raise reply.fault('no "data" list of models') from None


def unwritable(folder: Path) -> str:
    """Why files cannot be made under ``folder`` and its subfolders ("" when they can): a file
    in the way, or no write permission on the folder, on one of its subfolders or on the
    nearest existing folder above it (the folder itself is not created)."""
    folder = Path(folder)
    existing = next((p for p in (folder, *folder.parents) if p.exists()), None)
    if existing is None:
        return ""
    if not existing.is_dir():
        return f"{existing} is a file, not a folder"
    subfolders = [p for p in existing.glob("??") if p.is_dir()] if existing == folder else []
    for p in (existing, *subfolders):
        if not os.access(p, os.W_OK | os.X_OK):
            return f"no permission to write in {p}"
    return ""


class ResponseCache:
    """A content-addressed store of answers under ``root``: one JSON file per request,
    ``root/KEY[:2]/KEY.json`` with KEY = :func:`request_hash` of the request body, holding the
    request itself (a lookup checks it, so a hash collision or a damaged file is a miss) and
    the answer's fields. Written atomically, so a killed run leaves no half file; a folder of
    them can be copied with results so that others replay a run without the model."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)

    def path(self, key: str) -> Path:
        return self.root / key[:2] / f"{key}.json"

    def get(self, key: str, request: dict) -> dict | None:
        """The stored record of ``request`` (None: not stored, unreadable, or another request)."""
        try:
            rec = json.loads(self.path(key).read_text(encoding="utf-8"))
        except (OSError, ValueError, RecursionError):
            return None
        if not isinstance(rec, dict) or rec.get("format") != CACHE_FORMAT or rec.get("request") != request:
            return None
        return rec

    def put(self, key: str, request: dict, **answer: Any) -> None:
        """Store ``answer``'s fields (JSON types) for ``request`` under ``key``."""
        write_atomic(self.path(key), dumps_json({"format": CACHE_FORMAT, "key": key, "request": request,
                                                 **answer}))

    def __len__(self) -> int:
        return sum(1 for _ in self.root.glob("??/*.json")) if self.root.is_dir() else 0
