"""Agent identity: a fingerprint of what an agent *is*, stored with every episode it drove.

The store keys episodes by the agent's name; the fingerprint tells two agents of one name apart
(edited code, a retrained checkpoint), so a rerun never reports an earlier agent's rows as the
current one's. What it covers, by kind of agent:

* an agent that declares its own ``fingerprint`` (a non-empty string on the class, the factory
  or an instance's factory): that string, hashed;
* a remote agent (``remote:URL``): what the server reports about itself in ``GET /info``
  (``fingerprint``, which ``icrsumo serve-agent`` computes from the agent it serves);
* any other class or function (built-in, learned, ``module:Class``, ``path/file.py:Class``, an
  agent class, function or instance given to the Python API): its code, its checkpoint and its
  settings:

  - **code**: the source file of the class, of each of its base classes and of the factory
    function, and every module those files reach through their imports, transitively: every
    import form (``import a.b.c``, ``from a.b import c``, ``from . import x``, ``from ..x import
    y``), at module level or inside functions, with the packages (``__init__.py``) each import
    runs. Imports are read from the files' syntax trees (:mod:`ast`) and resolved as the import
    system would, without importing anything: a module already imported is the one in
    ``sys.modules``; else a top-level name is found with :func:`importlib.util.find_spec`
    (which imports nothing for a top-level name) and a submodule in its package's folders with
    :class:`importlib.machinery.PathFinder`. Imports under ``if TYPE_CHECKING:`` never run and
    are skipped; a name built at run time (``importlib.import_module(name)``) is not followed.
    Code a user does not edit is not read: the standard library and files of installed
    distributions (site-packages; an editable install's files live in its project folder and
    are read). Where the class, a base class or the function itself is such installed code (a
    plugin, the built-in agents of an icrsumo installed from a wheel), its distribution's name
    and version stand for it. Each file counts by its module name (a path agent's own file by its
    file name) and its bytes, so the same files in another folder or checkout are the same agent;
  - **checkpoint**: the SHA-256 of each file named by ``checkpoint`` or ``path`` (a path or a
    list of paths; an instance's own, else the class's);
  - **settings**: an instance's attributes (an agent instance given to the Python API), and
    the arguments bound into a factory function (``functools.partial``, defaults, closures);
  - and the class's qualified name: two classes of one file are two agents.

A fingerprint is ``sha256:`` and 64 hex digits; :func:`short` shows its first 12.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib.machinery
import importlib.util
import inspect
import io
import pickle
import site
import sys
import sysconfig
import types
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from icrsumo.core.fsio import sha256_file

#: module-name prefix of an agent file loaded by path (``path/file.py:Class``); the rest of its
#: name changes with the file's folder, so :mod:`icrsumo.agents.identity` names it by its file
PATH_MODULE_PREFIX = "icrsumo_user_agent_"

_PREFIX = "sha256:"
#: attributes that name an agent's checkpoint file(s)
_CHECKPOINT_ATTRS = ("checkpoint", "path")


def _roots(*folders: str) -> tuple[str, ...]:
    return tuple(sorted({str(Path(f).resolve()) + "/" for f in folders if f}))


_PATHS = sysconfig.get_paths()
#: the standard library's folders: code that is the interpreter's, never an agent's own
_STDLIB = _roots(_PATHS["stdlib"], _PATHS["platstdlib"])
#: site-packages folders: installed distributions (an editable install's files live elsewhere)
_SITE = _roots(_PATHS["purelib"], _PATHS["platlib"], *getattr(site, "getsitepackages", list)(),
               site.getusersitepackages())


def short(fp: str) -> str:
    """The first 12 hex digits of a fingerprint (for messages)."""
    return fp.removeprefix(_PREFIX)[:12] or "(none)"


def of_text(text: str) -> str:
    """The fingerprint of a declared identity string."""
    return _PREFIX + hashlib.sha256(text.encode("utf-8")).hexdigest()


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
    starts = [*(inspect.getmro(target) if isinstance(target, type) else (target,)), *_callables(fn)]
    code = _code(starts)
    qualname = getattr(target, "__qualname__", repr(target))
    if not code:  # no source to read (a C extension, a class typed in a REPL): its full name
        qualname = f"{getattr(target, '__module__', '?')}.{qualname}"
    h = hashlib.sha256()  # the qualified name first: two classes of one file are two agents
    h.update(b"name\0" + qualname.encode() + b"\0")
    for key, data in code:
        h.update(b"code\0" + key.encode() + b"\0" + data + b"\0")
    for digest in _checkpoints(instance, target):
        h.update(b"checkpoint\0" + digest.encode() + b"\0")
    for settings in (instance, *_bound(fn)):
        if settings is not None:
            h.update(b"settings\0" + _settings(settings) + b"\0")
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


# ------------------------------------------------------------------ checkpoints and settings
def _checkpoints(instance: object, target: object) -> list[str]:
    """SHA-256 of each checkpoint file the instance names, else the class (``checkpoint`` or
    ``path``: a path or a list of paths; what is not a file is no checkpoint)."""
    for holder in (instance, target):
        for attr in _CHECKPOINT_ATTRS:
            value = getattr(holder, attr, None) if holder is not None else None
            paths = value if isinstance(value, (list, tuple)) else [value]
            files = [Path(p) for p in paths if isinstance(p, (str, Path)) and str(p) and Path(p).is_file()]
            if files:
                return [sha256_file(f) for f in files]
    return []


def _callables(fn: object) -> list[object]:
    """The functions whose code a factory function runs: itself, or a partial's function."""
    if fn is None:
        return []
    return [fn.func] if isinstance(fn, functools.partial) else [fn]


def _bound(fn: object) -> list[object]:
    """The settings bound into a factory function: a partial's arguments, a function's
    defaults and the values its closure holds."""
    if isinstance(fn, functools.partial):
        return [(fn.args, fn.keywords)]
    if isinstance(fn, types.FunctionType):
        cells = tuple(c.cell_contents for c in fn.__closure__ or () if _filled(c))
        return [(fn.__defaults__, fn.__kwdefaults__, cells)]
    return []


def _filled(cell: types.CellType) -> bool:
    try:
        cell.cell_contents  # noqa: B018 - an empty cell raises
    except ValueError:
        return False
    return True


class _StablePickler(pickle.Pickler):
    """Pickles settings the same in every process and folder: classes and functions as their
    qualified names (a path agent's module name changes with its folder and the process) and
    sets in sorted order (a set of strings iterates in the process's hash-seed order)."""

    def persistent_id(self, obj: object) -> object:
        if isinstance(obj, (type, types.FunctionType, types.BuiltinFunctionType)):
            return f"global {getattr(obj, '__qualname__', repr(obj))}"
        if isinstance(obj, (set, frozenset)):
            return type(obj).__name__, tuple(sorted(obj, key=repr))
        return None


def _settings(obj: object) -> bytes:
    """The bytes of ``obj``'s settings (an unpicklable object is known by its class)."""
    buf = io.BytesIO()
    try:
        _StablePickler(buf, protocol=4).dump(obj)
    except Exception:  # noqa: BLE001 - an unpicklable instance is known by its class
        return b"unpicklable " + type(obj).__qualname__.encode()
    return buf.getvalue()


# ----------------------------------------------------------------------------- code reached
@dataclass(frozen=True)
class _Source:
    """A module the agent's code reaches: its ``key`` (module name, or a path agent's file
    name), its resolved ``file`` and the ``package`` its relative imports start from."""

    key: str
    file: Path
    package: str


def _code(starts: Iterable[object]) -> list[tuple[str, bytes]]:
    """(key, bytes) of every file the objects ``starts`` are defined in and reach, sorted by
    key; installed code stands as ``dist==version`` (with empty bytes)."""
    sources: list[_Source] = []
    tokens: set[str] = set()
    for obj in starts:
        source, token = _defining(obj)
        if source is not None:
            sources.append(source)
        elif token:
            tokens.add(token)
    out = [(key, file.read_bytes()) for file, key in _reach(sources).items()]  # a key may repeat
    return sorted(out + [(f"installed {t}", b"") for t in tokens])


def _defining(obj: object) -> tuple[_Source | None, str]:
    """The source of the module that defines ``obj``, or (None, its distribution as
    ``name==version``) where that module is installed code, or (None, "") where it has no file
    (a built-in, the standard library, a REPL)."""
    module = sys.modules.get(getattr(obj, "__module__", None) or "")
    file = _file(getattr(module, "__file__", None))
    if module is None or file is None:
        return None, ""
    name = module.__name__
    if _is_installed(file):
        return None, _distribution(name) if str(file).startswith(_SITE) else ""
    key = file.name if name == "__main__" or name.startswith(PATH_MODULE_PREFIX) else name
    package = getattr(module, "__package__", None) or ""
    return _Source(key, file, package), ""


def _reach(starts: list[_Source]) -> dict[Path, str]:
    """File -> key of the ``starts`` and of every editable module they import, transitively."""
    seen: dict[Path, str] = {}
    todo = list(reversed(starts))
    while todo:
        src = todo.pop()
        if src.file in seen:
            continue
        seen[src.file] = src.key
        if src.file.suffix == ".py":
            for name in _imports(src):
                todo.extend(reversed(_resolve(name)))
    return seen


def _imports(src: _Source) -> Iterator[str]:
    """The absolute names the file of ``src`` may import: each ``import`` name, each ``from``
    module and each ``from`` module's imported names (a submodule or an attribute)."""
    try:
        tree = ast.parse(src.file.read_bytes())
    except (SyntaxError, ValueError, OSError):
        return
    for node in _runtime_nodes(tree):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            try:
                base = importlib.util.resolve_name("." * node.level + (node.module or ""), src.package) \
                    if node.level else node.module or ""
            except (ImportError, ValueError):  # a relative import beyond its top package
                continue
            yield base
            yield from (f"{base}.{a.name}" for a in node.names if a.name != "*")


def _runtime_nodes(tree: ast.AST) -> Iterator[ast.AST]:
    """Every node of ``tree`` outside ``if TYPE_CHECKING:`` bodies (imports there never run)."""
    todo = [tree]
    while todo:
        node = todo.pop()
        yield node
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and _is_type_checking(child.test):
                todo.extend(child.orelse)
            else:
                todo.append(child)


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _resolve(name: str) -> list[_Source]:
    """The editable modules that importing ``name`` runs: each package on the way and the module
    itself, up to the first part that is installed, built in or not found (nothing is imported)."""
    out: list[_Source] = []
    locations: list[str] | None = None
    parts = name.split(".")
    for i in range(len(parts)):
        full = ".".join(parts[: i + 1])
        if i and locations is None:  # the parent is a module, not a package: an attribute
            break
        found = _find(full, locations)
        if found is None:
            break
        file, locations = found
        if file is not None:
            if _is_installed(file):
                break
            is_package = locations is not None
            out.append(_Source(full, file, full if is_package else full.rpartition(".")[0]))
    return out


def _find(name: str, parent_locations: list[str] | None) -> tuple[Path | None, list[str] | None] | None:
    """(file, submodule folders) of module ``name`` as the import system would find it, or None."""
    module = sys.modules.get(name)
    if module is not None:
        path = getattr(module, "__path__", None)
        return _file(getattr(module, "__file__", None)), list(path) if path is not None else None
    try:
        if parent_locations is None:  # a top-level name: imports nothing
            spec = importlib.util.find_spec(name)
        else:
            spec = importlib.machinery.PathFinder.find_spec(name, parent_locations)
    except Exception:  # noqa: BLE001 - a broken finder or name: not followed
        return None
    if spec is None:
        return None
    file = _file(spec.origin) if spec.has_location else None
    locations = spec.submodule_search_locations
    return file, list(locations) if locations is not None else None


def _file(origin: object) -> Path | None:
    """The resolved file of a module's ``__file__`` / spec origin, or None when it has none."""
    if not isinstance(origin, str) or not origin:
        return None
    path = Path(origin)
    return path.resolve() if path.is_file() else None


def _is_installed(file: Path) -> bool:
    """Whether ``file`` is the standard library's or an installed distribution's."""
    return str(file).startswith(_SITE + _STDLIB)


@functools.cache
def _distribution(module: str) -> str:
    """``name==version`` of the installed distributions that provide ``module``'s top-level
    package (the top-level name itself when none declares it)."""
    from importlib.metadata import PackageNotFoundError, packages_distributions, version

    top = module.partition(".")[0]
    out = []
    for dist in sorted(set(packages_distributions().get(top, []))):
        try:
            out.append(f"{dist}=={version(dist)}")
        except PackageNotFoundError:
            out.append(dist)
    return " ".join(out) or top
