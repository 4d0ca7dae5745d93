"""Atomic file output: a reader never sees a half-written file or scenario folder."""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import re
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

_FLAT_LIST = re.compile(r"\[\s*((?:[^\[\]{}\"]|\"(?:[^\"\\]|\\.)*\")*?)\s*\]")


def dumps_json(obj: Any) -> str:
    """Canonical JSON text: key order as given, 1-space indent, lists of scalars on one line,
    trailing newline. The same object always gives the same bytes."""
    text = json.dumps(obj, indent=1, ensure_ascii=False, allow_nan=False)
    text = _FLAT_LIST.sub(lambda m: "[" + re.sub(r",\s+", ", ", m.group(1)) + "]", text)
    return text + "\n"


#: byte-order marks of encodings other than UTF-8, longest first
BOMS = ((b"\xff\xfe\x00\x00", "UTF-32"), (b"\x00\x00\xfe\xff", "UTF-32"), (b"\xff\xfe", "UTF-16"),
         (b"\xfe\xff", "UTF-16"))


def unreadable(path: Path, what: str, fix: str, err: OSError) -> Exception:
    """The InputError of an OSError met reading a user's file ``path`` (``what`` names it)."""
    from .errors import InputError

    if isinstance(err, FileNotFoundError):
        return InputError(path, "", f"{what} not found", fix or "check the path")
    if isinstance(err, IsADirectoryError):
        return InputError(path, "", f"is a folder, not a file ({what})", fix or "pass the file")
    if isinstance(err, PermissionError):
        return InputError(path, "", f"{what} is not readable (permission denied)",
                          "check the file's permissions")
    return InputError(path, "", f"{what} cannot be read ({err.strerror or err})", fix or "check the path")


def read_text(path: Path, what: str, fix: str = "") -> str:
    """The UTF-8 text of a user's file (a UTF-8 byte-order mark is dropped); InputErrors for a
    missing file, a folder, no permission, and text that is not UTF-8 (UTF-16 named as such).
    ``what`` names the file in the message ("template bank"), ``fix`` says how to get it right."""
    from .errors import InputError

    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise unreadable(path, what, fix, err) from None
    for bom, name in BOMS:
        if raw.startswith(bom):
            raise InputError(path, "", f"{what} is {name}-encoded, not UTF-8", "save it as UTF-8")
    nul = raw.find(b"\x00")
    if nul >= 0:
        line = raw[:nul].count(b"\n") + 1
        raise InputError(path, f"line {line}", f"{what} holds NUL bytes (UTF-16 without a byte-order mark?)",
                         "save it as UTF-8")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        line = raw[:err.start].count(b"\n") + 1
        raise InputError(path, f"line {line}", f"{what} is not UTF-8 text (byte {err.start})",
                         "save it as UTF-8") from None


def no_constants(name: str) -> Any:
    """``json.loads`` hook: NaN and Infinity are no JSON numbers (a ValueError)."""
    raise ValueError(f"{name} is not a JSON number")


def no_duplicates(pairs: list[tuple[str, Any]]) -> dict:
    """``json.loads`` hook: a key twice in one object is a ValueError naming it."""
    out: dict = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"duplicate key {key[:60]!r} appears twice in one object")
        out[key] = value
    return out


def lone_surrogate(obj: Any, place: str = "") -> tuple[str, int] | None:
    """(where, character number from 1) of the first lone surrogate in the strings (keys
    included) of a parsed JSON value, None when there is none. JSON can write one (a
    ``\\ud800`` escape without the other half of its pair), but no text file can hold it."""
    if isinstance(obj, str):
        try:
            obj.encode("utf-8")
        except UnicodeEncodeError as err:
            return place, err.start + 1
        return None
    items = obj.items() if isinstance(obj, dict) else enumerate(obj) if isinstance(obj, list) else ()
    for key, value in items:
        where = f"{place}[{key}]" if isinstance(key, int) else f"{place}.{key}" if place else str(key)
        found = (lone_surrogate(key, f"{where} (the key)") if isinstance(key, str) else None) \
            or lone_surrogate(value, where)
        if found is not None:
            return found
    return None


def check_surrogates(obj: Any, text: str, path: Path, what: str) -> Any:
    """``obj`` (parsed from the JSON ``text`` of ``path``) when none of its strings holds a lone
    surrogate; an InputError naming the place and the character otherwise."""
    from .errors import InputError, visible

    found = lone_surrogate(obj) if "\\u" in text else None
    if found is not None:
        where, at = found
        raise InputError(path, visible(where) or "top level", f"{what} holds a lone surrogate at character "
                         f"{at} (a \\uD800-\\uDFFF escape without the other half of its pair), which no text "
                         "can hold", "write the character itself, or both halves of its pair")
    return obj


def read_json(path: Path, what: str, fix: str = "") -> Any:
    """A user's JSON file (:func:`read_text` and strict JSON: no NaN / Infinity, no key twice in
    one object, no lone surrogate in a string); InputErrors name the file, the line and column of
    a syntax error, and ``fix``."""
    return loads_json(read_text(path, what, fix), path, what, fix)


def loads_json(text: str, path: object, what: str, fix: str = "") -> Any:
    """The strict JSON document ``text`` (as :func:`read_json` reads a file's); InputErrors name
    ``path`` (the file, or where the text came from)."""
    from .errors import InputError

    try:
        doc = json.loads(text, parse_constant=no_constants, object_pairs_hook=no_duplicates)
    except RecursionError:
        raise InputError(path, "", f"{what} is nested too deeply to be read",
                         fix or "check the file") from None
    except json.JSONDecodeError as err:
        raise InputError(path, f"line {err.lineno}, column {err.colno}", f"malformed JSON ({err.msg})",
                         fix or f"fix the {what}'s JSON syntax there") from None
    except ValueError as err:
        raise InputError(path, "", f"malformed JSON ({err})",
                         fix or "use finite numbers and unique keys") from None
    return check_surrogates(doc, text, path, what)


def read_json_doc(path: Path, fmt: str, what: str, fix: str) -> dict:
    """A JSON document whose ``format`` key must be ``fmt``; problems are InputErrors naming
    the file (``what`` names the document, ``fix`` the command that writes it)."""
    from .errors import InputError, short

    path = Path(path)
    doc = read_json(path, what, fix)
    if not isinstance(doc, dict) or doc.get("format") != fmt:
        found = doc.get("format") if isinstance(doc, dict) else None
        raise InputError(path, "format", f"unsupported format {short(found)} (expects {fmt})", fix)
    return doc


def check_out_dir(path: Path, option: object = None) -> None:
    """An InputError unless ``path`` is (or can be made) a writable folder: not a file, and
    the folder or its nearest existing parent writable (errors naming ``option``, default the
    field ``out``). Nothing is created here."""
    from .errors import Field, InputError

    option = option or Field("out")

    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(option, str(path), "is a file, not a folder", "give a folder (new or existing)")
    probe = path
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise InputError(option, str(path), f"{probe} is a file, so the folder cannot be made",
                         "give a folder path")
    if not os.access(probe, os.W_OK | os.X_OK):
        where = "the folder" if probe == path else f"its parent {probe}"
        raise InputError(option, str(path), f"{where} is not writable", "give a folder you can write to")


@dataclass(frozen=True)
class OutFolder:
    """What a command's out folder was before it started (absent, or an empty folder), so that a
    refused run can take back what it wrote (:meth:`undo`). Take it with :meth:`before`."""

    path: Path
    fresh: bool
    empty: bool

    @classmethod
    def before(cls, path: Path) -> OutFolder:
        path = Path(path)
        fresh = not path.exists()
        empty = not fresh and path.is_dir() and all(p.name == LOCK_NAME for p in path.iterdir())
        return cls(path, fresh, empty)

    def undo(self) -> None:
        """Remove a folder that was absent; empty one that was empty (the user's: kept), the
        run's lock file (:class:`FolderLock`) aside."""
        if self.fresh:
            shutil.rmtree(self.path, ignore_errors=True)
        elif self.empty:
            for child in self.path.iterdir():
                if child.name == LOCK_NAME:
                    continue
                shutil.rmtree(child, ignore_errors=True) if child.is_dir() else child.unlink(missing_ok=True)


#: the lock file of an out folder while a run owns it
LOCK_NAME = ".icrsumo.lock"


class FolderLock:
    """One run owns an out folder: an exclusive ``flock`` on ``OUT/.icrsumo.lock`` (holding the
    owner's pid), taken before the folder's configuration is checked and held until the run
    ends; the system releases it when the process dies, however it dies. A second run on the
    folder meanwhile is an InputError naming the owner's pid (``busy_fix`` says what to do), a
    folder that cannot be written (a read-only disk) one saying so. The folder is made when missing;
    on leaving, the lock file goes, and so does a folder this lock made that is then empty (a
    refused run leaves nothing behind)."""


    def __init__(self, path: Path, busy_fix: str = "") -> None:
        self.path = Path(path)
        from .errors import Field

        #: what a run that finds the folder taken should do (given per command)
        self.busy_fix = busy_fix or f"wait for it to end, or use another {Field('out')} folder"
        self._fd: int | None = None
        self._made = False

    def __enter__(self) -> FolderLock:
        import fcntl

        from .errors import InputError

        self._made = not self.path.exists()
        self.path.mkdir(parents=True, exist_ok=True)
        lock = self.path / LOCK_NAME
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as err:
            if err.errno not in (errno.EACCES, errno.EPERM, errno.EROFS):
                raise
            raise InputError(self.path, "", f"the folder is not writable ({err.strerror}), and this command "
                             "writes into it", "make the folder writable, or copy it somewhere writable and "
                             "run the command on the copy") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            owner = os.read(fd, 32).decode("ascii", "replace").strip() or "?"
            os.close(fd)
            raise InputError(self.path, "", f"another icrsumo run (pid {owner}) is using this folder",
                             self.busy_fix) from None
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode("ascii"))
        self._fd = fd
        return self

    def __exit__(self, *exc: object) -> None:
        if self._fd is None:
            return
        (self.path / LOCK_NAME).unlink(missing_ok=True)  # while still held: no one else has it
        os.close(self._fd)                                # releases the lock
        self._fd = None
        if self._made:
            with contextlib.suppress(OSError):
                self.path.rmdir()                         # only when empty


#: longest file name icrsumo derives from a name or an id (most file systems allow 255 bytes)
MAX_FILE_NAME = 120


def bounded_name(name: str, original: str | None = None, limit: int = MAX_FILE_NAME) -> str:
    """A file name (``name``: already made of safe characters) of at most ``limit`` characters:
    a longer one is cut and ends with ``-`` and 8 hex digits of the SHA-256 of ``original``
    (default ``name``), so that names that differ only past the cut stay apart."""
    if len(name) <= limit:
        return name
    digest = hashlib.sha256((original if original is not None else name).encode("utf-8", "replace"))
    return f"{name[:limit - 9]}-{digest.hexdigest()[:8]}"


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
