"""The package's import graph (every import statement, also those inside functions): no cycle,
libsumo imported by the simulator backend alone, and no import from ``agents/`` or ``learn/``
into the closed loop's internals (they may use ``icrsumo.sim.episode`` and
``icrsumo.sim.callbacks``, the loop's public side)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import icrsumo

ROOT = Path(icrsumo.__file__).resolve().parent
#: the loop's internals: backend, frames, sensors, drivable area
LOOP_INTERNALS = ("icrsumo.sim.backend", "icrsumo.sim.frame", "icrsumo.sim.sensors", "icrsumo.sim.drivable")


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """icrsumo modules ``name`` imports (a ``from X import y`` names X.y when that is a module)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    typing_only = {id(n) for block in ast.walk(tree)
                   if isinstance(block, ast.If) and _is_type_checking(block.test)
                   for stmt in block.body for n in ast.walk(stmt)}
    found: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in typing_only:  # `if TYPE_CHECKING:` imports never run
            continue
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("icrsumo"):
                    found.add(alias.name)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if not target.startswith("icrsumo"):
                continue
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                found.add(sub if sub in modules else target)
    return {m for m in found if m in modules and m != name}


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_walker_sees_function_level_imports():
    graph = _graph()
    assert "icrsumo.sim.episode" in graph["icrsumo.learn.collect"]  # imported inside a function
    assert "icrsumo.sim.backend" in graph["icrsumo.sim.episode"]


def test_no_import_cycle():
    assert _cycles(_graph()) == []


def test_agents_and_learn_stay_out_of_the_loop_internals():
    bad = sorted((name, dep) for name, deps in _graph().items()
                 if name.startswith(("icrsumo.agents", "icrsumo.learn"))
                 for dep in deps if dep.startswith(LOOP_INTERNALS))
    assert bad == []


def _top_level_names(path: Path) -> set[str]:
    names = set()
    for n in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(n, ast.Import):
            names |= {a.name.split(".")[0] for a in n.names}
        elif isinstance(n, ast.ImportFrom) and not n.level:
            names.add((n.module or "").split(".")[0])
    return names


def test_only_the_backend_imports_libsumo():
    users = sorted(name for name, path in _modules().items() if "libsumo" in _top_level_names(path))
    assert users == ["icrsumo.sim.backend"]


def test_only_the_inference_runtime_imports_onnxruntime():
    users = sorted(name for name, path in _modules().items() if "onnxruntime" in _top_level_names(path))
    assert users == ["icrsumo.learn.runtime"]


#: a Sphinx cross-reference to something of the package (``:mod:`~icrsumo.agents.watch```)
_XREF = re.compile(r":(?:mod|func|class|data|meth|attr|exc):`~?(icrsumo(?:\.\w+)+)`")


def _top_level_defs(path: Path) -> set[str]:
    """Names a module defines or imports at its top level."""
    names: set[str] = set()
    for n in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(n.name)
        elif isinstance(n, (ast.Assign, ast.AnnAssign)):
            targets = n.targets if isinstance(n, ast.Assign) else [n.target]
            names |= {t.id for t in targets if isinstance(t, ast.Name)}
            if isinstance(n.value, ast.Dict):  # the names a package imports on first use
                names |= {k.value for k in n.value.keys
                          if isinstance(k, ast.Constant) and isinstance(k.value, str)}
        elif isinstance(n, (ast.Import, ast.ImportFrom)):
            names |= {(a.asname or a.name).split(".")[0] for a in n.names}
    return names


def test_docstrings_name_modules_that_exist():
    """Every cross-reference to the package in its docstrings names a module that exists (and a
    name that module defines): none is left behind when a module moves."""
    modules = _modules()
    bad = []
    for name, path in modules.items():
        for ref in _XREF.findall(path.read_text(encoding="utf-8")):
            parts = ref.split(".")
            k = max((i for i in range(1, len(parts) + 1) if ".".join(parts[:i]) in modules), default=0)
            if k == 0 or (k < len(parts) and parts[k] not in _top_level_defs(modules[".".join(parts[:k])])):
                bad.append(f"{name}: {ref}")
    assert bad == []


def test_the_bundled_suite_pipeline_keeps_its_old_name_and_one_default_suite():
    """``icrsumo.bundled`` is the bundled-suite pipeline, ``icrsumo.cache`` (its old name) re-exports
    it, and the default suite is defined once, in ``icrsumo.defaults``."""
    import icrsumo.bundled
    import icrsumo.cache

    assert icrsumo.cache.bundled_route is icrsumo.bundled.bundled_route
    assert icrsumo.cache.cache_root is icrsumo.bundled.cache_root
    defined = sorted(name for name, path in _modules().items()
                     for n in ast.parse(path.read_text(encoding="utf-8")).body if isinstance(n, ast.Assign)
                     for t in n.targets if isinstance(t, ast.Name) and t.id == "DEFAULT_SUITE")
    assert defined == ["icrsumo.defaults"]
