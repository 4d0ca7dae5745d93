"""The package's import graph (every import statement, also those inside functions): no cycle,
libsumo imported by the simulator backend alone, and no import from ``agents/`` or ``learn/``
into the closed loop's internals (they may use ``icrsumo.sim.episode`` and
``icrsumo.sim.callbacks``, the loop's public side)."""

from __future__ import annotations

import ast
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
