"""The package's import graph (every import statement, also those inside functions): no cycle,
libsumo imported by the simulator backend alone, no import from ``agents/`` or ``learn/`` into
the closed loop's internals (they may use ``icrsumo.sim.episode`` and ``icrsumo.sim.callbacks``,
the loop's public side), the layers (:data:`LAYERS`) never imported upwards, the command line
(``icrsumo.app.cli``) on top, imported by nothing of the library, and the old module names still
importing."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

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


#: the layers, bottom to top (docs/layout.md): a module may import its own layer and those below
#: it, never one above. A module's layer is the longest prefix of its name in this table.
LAYERS = (
    ("icrsumo.core",),
    ("icrsumo.world",),
    ("icrsumo.scoring", "icrsumo.render"),
    ("icrsumo.instructions",),
    ("icrsumo.agents",),
    ("icrsumo.guards",),
    ("icrsumo.agents.hosting",),
    ("icrsumo.sim",),
    ("icrsumo.learn",),
    ("icrsumo.results",),
    ("icrsumo.reporting",),
    ("icrsumo.evaluation",),
    ("icrsumo.app",),
    ("icrsumo.app.cli", "icrsumo.compat", "icrsumo.__main__"),
)


def _layer(module: str) -> int:
    best, found = -1, -1
    for i, prefixes in enumerate(LAYERS):
        for top in prefixes:
            if (module == top or module.startswith(top + ".")) and len(top) > best:
                best, found = len(top), i
    return found


def test_every_module_has_a_layer():
    assert sorted(m for m in _modules() if m != "icrsumo" and _layer(m) < 0) == []


def test_no_import_points_up_a_layer():
    """Each import stays in its layer or goes down (``icrsumo/__init__`` is exempt: it installs
    the old names and exports the API lazily)."""
    bad = sorted((name, dep) for name, deps in _graph().items() if name != "icrsumo"
                 for dep in deps if _layer(dep) > _layer(name))
    assert bad == []


def test_the_command_line_is_the_top_layer():
    """Nothing of the library imports the command line: ``icrsumo.app.cli`` is imported by its own
    modules and ``icrsumo.__main__`` alone."""
    graph = _graph()

    def cli(module: str) -> bool:
        return module == "icrsumo.app.cli" or module.startswith("icrsumo.app.cli.")

    bad = sorted((name, dep) for name, deps in graph.items() for dep in deps
                 if cli(dep) and not cli(name) and name != "icrsumo.__main__")
    assert bad == []


def test_old_module_names_give_the_moved_modules():
    """Every name in :data:`icrsumo.compat.MOVED` imports, as the very module at its new place,
    with a DeprecationWarning that names the new place; ``python -m icrsumo`` and the console
    script's target exist."""
    import importlib
    import sys
    import warnings

    from icrsumo.compat import MOVED

    for old, new in MOVED.items():
        sys.modules.pop(f"icrsumo.{old}", None)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            module = importlib.import_module(f"icrsumo.{old}")
        assert module is importlib.import_module(f"icrsumo.{new}"), old
        assert any(issubclass(w.category, DeprecationWarning) and f"icrsumo.{new}" in str(w.message)
                   for w in caught), old
        assert f"icrsumo.{new}" in _modules(), new
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from icrsumo import errors, routes
        from icrsumo.core import errors as errors_now
    assert errors is errors_now and routes.__name__ == "icrsumo.world.routes"
    script = re.search(r'^icrsumo = "([\w.]+):(\w+)"', (ROOT.parent / "pyproject.toml").read_text(), re.M)
    assert script and hasattr(importlib.import_module(script.group(1)), script.group(2))


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


def test_only_the_renderer_imports_cv2():
    users = sorted(name for name, path in _modules().items() if "cv2" in _top_level_names(path))
    assert users == ["icrsumo.render.bev", "icrsumo.render.video"]


def test_torch_and_matplotlib_stay_in_their_corners():
    """torch: the learned agents' float side, GPU batching and the device check; matplotlib:
    the report's figures (docs/layout.md)."""
    torch = sorted(name for name, path in _modules().items() if "torch" in _top_level_names(path))
    outside_learn = [n for n in torch if not n.startswith("icrsumo.learn.")]
    assert outside_learn == ["icrsumo.agents.hosting.batched", "icrsumo.core.devices"]
    plots = [name for name, path in _modules().items() if "matplotlib" in _top_level_names(path)]
    assert plots and [n for n in plots if not n.startswith("icrsumo.reporting.")] == []


def test_only_the_inference_runtime_imports_onnxruntime():
    users = sorted(name for name, path in _modules().items() if "onnxruntime" in _top_level_names(path))
    assert users == ["icrsumo.learn.runtime"]


#: a Sphinx cross-reference to something of the package (``:mod:`~icrsumo.agents.hosting.watch```)
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
    """``icrsumo.evaluation.bundled`` is the bundled-suite pipeline, ``icrsumo.cache`` (its old
    name) still gives it, and the default suite is defined once, in ``icrsumo.core.defaults``."""
    import warnings

    import icrsumo.evaluation.bundled
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import icrsumo.cache

    assert icrsumo.cache.bundled_route is icrsumo.evaluation.bundled.bundled_route
    assert icrsumo.cache.cache_root is icrsumo.evaluation.bundled.cache_root
    defined = sorted(name for name, path in _modules().items()
                     for n in ast.parse(path.read_text(encoding="utf-8")).body if isinstance(n, ast.Assign)
                     for t in n.targets if isinstance(t, ast.Name) and t.id == "DEFAULT_SUITE")
    assert defined == ["icrsumo.core.defaults"]


REPO = ROOT.parent
#: the scripts outside the package: they use the package's public names alone (issue 44)
SCRIPT_DIRS = ("tools", "benchmarks")


def _private_uses(source: str, tools: set[str]) -> list[str]:
    """Private names (``_x``, not dunders) of icrsumo or of the tools that ``source`` imports or
    reads as an attribute of a module it imported (``from icrsumo.m import _x``, ``m._x``,
    ``icrsumo.m._x``), each as ``line: module.name``."""
    def ours(module: str) -> bool:
        return module.split(".")[0] in {"icrsumo", *tools}

    def private(name: str) -> bool:
        return name.startswith("_") and not name.startswith("__")

    tree = ast.parse(source)
    bound: dict[str, str] = {}  # local name -> the module (or module's name) it stands for
    found: list[str] = []
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom) and not n.level and ours(n.module or ""):
            for a in n.names:
                if private(a.name):
                    found.append(f"{n.lineno}: {n.module}.{a.name}")
                bound[a.asname or a.name] = f"{n.module}.{a.name}"
        elif isinstance(n, ast.Import):
            for a in n.names:
                if ours(a.name):
                    bound[a.asname or a.name.split(".")[0]] = a.name if a.asname else a.name.split(".")[0]
    for n in ast.walk(tree):
        if isinstance(n, ast.Attribute) and private(n.attr):
            base = n.value
            while isinstance(base, ast.Attribute):
                base = base.value
            if isinstance(base, ast.Name) and base.id in bound:
                found.append(f"{n.lineno}: {ast.unparse(n)}")
    return sorted(found)


def test_the_private_name_scan_finds_every_form():
    src = ("from icrsumo.world.convert import _sumocfg, ConvertOptions\n"
           "import icrsumo.sim.drivable as d\nimport icrsumo.render\nfrom icrsumo.learn import minilm\n"
           "from make_routes import _onward\nimport os\n"
           "d._polygonal(1); icrsumo.render._layer; minilm._PARTS; os._exit; d.__name__; minilm.WIDTH\n")
    assert _private_uses(src, {"make_routes"}) == [
        "1: icrsumo.world.convert._sumocfg", "5: make_routes._onward",
        "7: d._polygonal", "7: icrsumo.render._layer", "7: minilm._PARTS"]


def test_tools_and_benchmarks_use_public_names_only():
    """tools/ and benchmarks/ import only public names of icrsumo and of each other: what they
    need is the package's (or the tool's) documented interface, not its internals."""
    scripts = sorted(p for d in SCRIPT_DIRS for p in (REPO / d).glob("*.py"))
    tools = {p.stem for p in scripts}
    assert len(scripts) > 10
    bad = [f"{p.relative_to(REPO)}:{use}" for p in scripts
           for use in _private_uses(p.read_text(encoding="utf-8"), tools)]
    assert bad == []


def test_split_modules_keep_their_names_at_the_old_place():
    """The modules split for size (issue 44) re-export every public name from where it was."""
    import icrsumo.agents.driver
    import icrsumo.agents.llm
    import icrsumo.agents.llm_request
    import icrsumo.agents.privileged
    import icrsumo.agents.speed
    import icrsumo.render
    import icrsumo.render.bev
    import icrsumo.render.video

    assert icrsumo.agents.privileged.PathDriver is icrsumo.agents.driver.PathDriver
    assert icrsumo.agents.privileged.arrival_time is icrsumo.agents.speed.arrival_time
    assert icrsumo.agents.privileged.STANDING_WAIT == icrsumo.agents.speed.STANDING_WAIT
    assert icrsumo.agents.privileged.HORIZON == icrsumo.agents.driver.HORIZON
    assert icrsumo.agents.llm.parse_spec is icrsumo.agents.llm_request.parse_spec
    assert icrsumo.agents.llm.Scene is icrsumo.agents.llm_request.Scene
    assert icrsumo.render.BevRenderer is icrsumo.render.bev.BevRenderer
    assert icrsumo.render.VideoWriter is icrsumo.render.video.VideoWriter
    for module in (icrsumo.agents.privileged, icrsumo.agents.llm, icrsumo.render):
        assert [n for n in module.__all__ if not hasattr(module, n)] == []


def test_the_torch_models_keep_their_names_at_the_old_place():
    pytest.importorskip("torch")
    import icrsumo.learn.nets as nets
    from icrsumo.learn.nets import checkpoint, models, policy, trainer

    assert nets.Policy is policy.Policy and nets.onnx_bytes is policy.onnx_bytes
    assert nets.Trainer is trainer.Trainer and nets.read_checkpoint is checkpoint.read_checkpoint
    assert nets.BevLanguageNet is models.BevLanguageNet and nets.pick_device is models.pick_device
    assert [n for n in nets.__all__ if not hasattr(nets, n)] == []
