"""Talking to an OpenAI-compatible chat-completions server (vLLM, llama.cpp's server, a hosted
API): canonical request bytes and their SHA-256 (the cache key), one bounded HTTP exchange with
a one-line reason for every failure, the answer text of a response body, the models a server
serves, and a content-addressed response cache on disk.

Used by the LLM instruction generator (:mod:`icrsumo.instructions.llm`) and the LLM
instruction interpreter (:mod:`icrsumo.agents.llm`). Standard library only.
"""

from __future__ import annotations

import hashlib
import http.client
import ipaddress
import json
import socket
import time
import urllib.error
import urllib.parse
import urllib.request
from pathlib import Path
from typing import Any

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


def _read_bounded(resp: Any, deadline: float, limit: int) -> bytes:
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
        if time.monotonic() > deadline:
            raise TimeoutError("timed out")


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


def exchange(url: str, data: bytes | None, *, api_key: str | None, timeout: float,
             limit: int = MAX_RESPONSE_BYTES) -> tuple[int, bytes]:
    """POST ``data`` (GET when None) to ``url``; returns (HTTP status, body bytes), the body
    read within ``timeout`` s and at most ``limit`` bytes. Transport failures raise
    :class:`Transport` (:class:`TooLarge` for an oversized body). A loopback server is reached
    directly, whatever ``*_proxy`` variables say."""
    headers = {"Accept": "application/json"}
    if data is not None:
        headers["Content-Type"] = "application/json"
    if api_key:
        headers["Authorization"] = f"Bearer {api_key}"
    req = urllib.request.Request(url, data=data, headers=headers, method="GET" if data is None else "POST")
    handlers = [urllib.request.ProxyHandler({})] if is_loopback(url) else []
    opener = urllib.request.build_opener(*handlers)
    deadline = time.monotonic() + timeout
    try:
        with opener.open(req, timeout=timeout) as resp:
            return resp.status, _read_bounded(resp, deadline, limit)
    except urllib.error.HTTPError as err:
        try:
            raw = _read_bounded(err, deadline, limit)
        except (OSError, http.client.HTTPException, Transport):
            raw = b""
        finally:
            err.close()
        return err.code, raw
    except Transport:
        raise
    except (urllib.error.URLError, http.client.HTTPException, OSError) as err:
        reason, unreachable = _reason(err)
        raise Transport(reason, unreachable=unreachable) from err


def http_problem(status: int, raw: bytes) -> str:
    """``HTTP 404: model not found``: a status and the error message of its body, one line."""
    detail = raw[:300].decode("utf-8", "replace")
    try:
        err = json.loads(raw)
        if isinstance(err, dict):
            inner = err.get("error", err.get("detail", err))
            detail = str(inner.get("message", inner) if isinstance(inner, dict) else inner)[:300]
    except (ValueError, RecursionError):
        pass
    detail = " ".join(detail.split())
    return f"HTTP {status}" + (f": {detail}" if detail else "")


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


def answer_text(raw: bytes) -> tuple[str, str]:
    """(``choices[0].message.content``, ``choices[0].finish_reason`` or "") of a
    chat-completions response body; :class:`Invalid` when the body has no answer text."""
    try:
        body = json.loads(raw)
    except (ValueError, RecursionError) as err:
        raise Invalid([f"response body is not JSON ({str(err)[:80]})"]) from None
    if not isinstance(body, dict):
        raise Invalid(["response body is not a JSON object"])
    choices = body.get("choices")
    if not isinstance(choices, list) or not choices or not isinstance(choices[0], dict):
        raise Invalid(["response has no choices[0]"])
    message = choices[0].get("message")
    content = message.get("content") if isinstance(message, dict) else None
    if not isinstance(content, str) or not content.strip():
        raise Invalid(["response has no choices[0].message.content text"])
    reason = choices[0].get("finish_reason")
    return content, reason if isinstance(reason, str) else ""


def served_models(endpoint: str, *, api_key: str | None, timeout: float) -> list[str] | None:
    """The model ids ``GET {endpoint}/models`` lists, or None when the server has no such list
    (any answer but a 200 with ``data: [{"id": ...}]``). :class:`Transport` when unreachable."""
    status, raw = exchange(models_url(endpoint), None, api_key=api_key, timeout=timeout, limit=1 << 20)
    if status != 200:
        if status in (401, 403):
            raise Transport(http_problem(status, raw))
        return None
    try:
        data = json.loads(raw).get("data")
        return [str(m["id"]) for m in data if isinstance(m, dict) and "id" in m]
    except (ValueError, RecursionError, AttributeError, TypeError):
        return None


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
