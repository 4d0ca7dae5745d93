"""Atomic file output: a reader never sees a half-written file or scenario folder."""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Any

_FLAT_LIST = re.compile(r"\[\s*((?:[^\[\]{}\"]|\"(?:[^\"\\]|\\.)*\")*?)\s*\]")


def dumps_json(obj: Any) -> str:
    """Canonical JSON text: key order as given, 1-space indent, lists of scalars on one line,
    trailing newline. The same object always gives the same bytes."""
    text = json.dumps(obj, indent=1, ensure_ascii=False, allow_nan=False)
    text = _FLAT_LIST.sub(lambda m: "[" + re.sub(r",\s+", ", ", m.group(1)) + "]", text)
    return text + "\n"


def read_json_doc(path: Path, fmt: str, what: str, fix: str) -> dict:
    """A JSON document whose ``format`` key must be ``fmt``; problems are InputErrors naming
    the file (``what`` names the document, ``fix`` the command that writes it)."""
    from .errors import InputError

    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(path, "", f"{what} not found", fix) from None
    except json.JSONDecodeError as err:
        raise InputError(path, f"line {err.lineno}", "malformed JSON", fix) from None
    if not isinstance(doc, dict) or doc.get("format") != fmt:
        found = doc.get("format") if isinstance(doc, dict) else None
        raise InputError(path, "format", f"unsupported format {found!r} (expects {fmt})", fix)
    return doc


def write_atomic(path: Path, data: str | bytes) -> None:
    """Write ``data`` to ``path`` via a temporary file in the same folder and ``os.replace``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    raw = data.encode("utf-8") if isinstance(data, str) else data
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.chmod(tmp, 0o644)
        with os.fdopen(fd, "wb") as fh:
            fh.write(raw)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def replace_dir_atomic(staging: Path, final: Path) -> None:
    """Move a fully written ``staging`` folder to ``final``, replacing an older one."""
    final = Path(final)
    if final.exists():
        old = final.with_name(f".{final.name}.old-{os.getpid()}")
        if old.exists():
            shutil.rmtree(old)
        os.replace(final, old)
        os.replace(staging, final)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(staging, final)


def sha256_file(path: Path) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


_HEADER_COMMENT = re.compile(r"\s*<!--.*?-->", re.S)


def strip_header_comments(text: str) -> str:
    """Remove the ``<!-- generated on DATE ... -->`` comments SUMO tools put before the root
    element, so that files are byte-identical across runs and folders."""
    decl_end = text.find("?>") + 2 if text.startswith("<?xml") else 0
    head, body = text[:decl_end], text[decl_end:]
    while True:
        m = _HEADER_COMMENT.match(body)
        if not m:
            break
        body = body[m.end():]
    return f"{head}\n{body.lstrip()}" if head else body.lstrip()
