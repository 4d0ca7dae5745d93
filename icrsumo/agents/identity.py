"""Agent identity: a fingerprint of what an agent *is*, stored with every episode it drove.

The store keys episodes by the agent's name; the fingerprint tells two agents of one name apart
(edited code, a retrained checkpoint), so a rerun never reports an earlier agent's rows as the
current one's. What it covers, by kind of agent:

* an agent that declares its own ``fingerprint`` (a non-empty string on the class, the factory
  or an instance's factory): that string, hashed;
* a learned agent (a ``checkpoint`` file): the checkpoint's SHA-256;
* a remote agent (``remote:URL``): what the server reports about itself in ``GET /info``
  (``fingerprint``, which ``icrsumo serve-agent`` computes from the agent it serves);
* any other class or function (built-in, ``module:Class``, ``path/file.py:Class``, an agent
  class or function given to the Python API): the source files that define it and the classes
  it derives from, with the modules that those files import from their own folder (an agent
  file and its helpers), and its qualified name.

A fingerprint is ``sha256:`` and 64 hex digits; :func:`short` shows its first 12.
"""

from __future__ import annotations

import ast
import hashlib
import inspect
import pickle
import sysconfig
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from ..fsio import sha256_file

_PREFIX = "sha256:"
#: folders whose files are the interpreter's and installed packages', never an agent's own
_SYSTEM = tuple(str(Path(p).resolve()) for p in {sysconfig.get_paths()[k] for k in ("stdlib", "platstdlib")})


def short(fp: str) -> str:
    """The first 12 hex digits of a fingerprint (for messages)."""
    return fp.removeprefix(_PREFIX)[:12] or "(none)"


def of_text(text: str) -> str:
    """The fingerprint of a declared identity string."""
    return _PREFIX + hashlib.sha256(text.encode("utf-8")).hexdigest()


def of_file(path: str | Path) -> str:
    """The SHA-256 of one file (a checkpoint)."""
    return _PREFIX + sha256_file(Path(path))


def fingerprint(factory: Callable[..., Any]) -> str:
    """The fingerprint of the agents ``factory`` makes (a class, a function, an
    :class:`~icrsumo.agents.registry.OnDevice` wrapper or a remote factory)."""
    target = getattr(factory, "agent_class", factory)  # OnDevice: the wrapped class
    instance = vars(factory).get("instance") if hasattr(factory, "__dict__") else None
    fn = vars(factory).get("fn") if hasattr(factory, "__dict__") else None
    declared = (_declared(instance, plain=True) if instance is not None else None) or \
        (_declared(fn, plain=True) if fn is not None else None) or _declared(factory) or _declared(target)
    if declared:
        return declared if declared.startswith(_PREFIX) and len(declared) == 71 else of_text(declared)
    for holder in (instance, target):  # an instance's own checkpoint, else the class's
        for attr in ("checkpoint", "path"):
            checkpoint = getattr(holder, attr, None) if holder is not None else None
            if isinstance(checkpoint, (str, Path)) and str(checkpoint) and Path(checkpoint).is_file():
                return of_file(checkpoint)
    files = sorted(set(_source_files(target)) | set(_source_files(getattr(factory, "fn", None))))
    qualname = getattr(target, "__qualname__", repr(target))
    if not files:  # no source to read (a C extension, a class typed in a REPL): its full name
        qualname = f"{getattr(target, '__module__', '?')}.{qualname}"
    h = hashlib.sha256()  # the qualified name first: two classes of one file are two agents
    h.update(qualname.encode() + b"\0")
    for f in files:  # by file name and bytes: the same files in another folder are the same agent
        h.update(Path(f).name.encode() + b"\0" + Path(f).read_bytes() + b"\0")
    if instance is not None:  # an instance given to the Python API: its settings too
        try:
            h.update(pickle.dumps(instance, protocol=4))
        except Exception:  # noqa: BLE001 - an unpicklable instance is known by its class
            h.update(b"unpicklable")
    return _PREFIX + h.hexdigest()


def _declared(obj: object, plain: bool = False) -> str | None:
    """A declared ``fingerprint`` string of ``obj`` (``plain``: read as an instance's attribute;
    else statically, so that a wrapper's forwarding does not count)."""
    if plain:
        value = getattr(obj, "fingerprint", None)
        return value if isinstance(value, str) and value.strip() else None
    value = inspect.getattr_static(obj, "fingerprint", None) if obj is not None else None
    if isinstance(value, property):
        try:
            value = getattr(obj, "fingerprint", None)
        except Exception:  # noqa: BLE001 - a property read on the class is no identity
            return None
    return value if isinstance(value, str) and value.strip() else None


def _own_file(obj: object) -> str | None:
    try:
        f = inspect.getsourcefile(obj)  # type: ignore[arg-type]
    except (TypeError, OSError):
        return None
    if f is None or not Path(f).is_file():
        return None
    resolved = str(Path(f).resolve())
    return None if resolved.startswith(_SYSTEM) else resolved


def _source_files(target: object) -> Iterator[str]:
    """The files defining ``target`` and its base classes, and the modules each such file
    imports from its own folder."""
    if target is None:
        return
    classes = inspect.getmro(target) if isinstance(target, type) else (target,)
    for obj in classes:
        f = _own_file(obj)
        if f is None:
            continue
        yield f
        yield from _sibling_imports(f)


def _sibling_imports(f: str) -> Iterator[str]:
    """The files of the modules that the source file ``f`` imports from its own folder (read
    from its import statements, so a constant imported from a helper counts too)."""
    folder = Path(f).parent
    try:
        tree = ast.parse(Path(f).read_text(encoding="utf-8"))
    except (SyntaxError, UnicodeDecodeError, OSError):
        return
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            heads = [a.name.split(".")[0] for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level <= 1:
            heads = [node.module.split(".")[0]] if node.module else [a.name for a in node.names]
        else:
            continue
        for head in heads:
            for cand in (folder / f"{head}.py", folder / head / "__init__.py"):
                if cand.is_file() and str(cand.resolve()) != f:
                    yield str(cand.resolve())
