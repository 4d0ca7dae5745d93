"""The package's size rules (issue 44, docs/layout.md): every module under 600 lines and every
function under 120, except where docs/layout.md says why a split would hurt."""

from __future__ import annotations

import ast
from pathlib import Path

import icrsumo

ROOT = Path(icrsumo.__file__).resolve().parent
LAYOUT = ROOT.parent / "docs" / "layout.md"
MODULE_LINES, FUNCTION_LINES = 600, 120
#: module path (or ``path:function``) -> why it is longer; each must be named in docs/layout.md
LONGER: dict[str, str] = {}


def _sources() -> dict[str, str]:
    return {str(p.relative_to(ROOT.parent)): p.read_text(encoding="utf-8")
            for p in sorted(ROOT.rglob("*.py"))}


def test_modules_stay_short():
    long = {path: text.count("\n") for path, text in _sources().items() if text.count("\n") > MODULE_LINES}
    assert {p: n for p, n in long.items() if p not in LONGER} == {}


def test_functions_stay_short():
    long = {}
    for path, text in _sources().items():
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > FUNCTION_LINES and f"{path}:{node.name}" not in LONGER:
                    long[f"{path}:{node.name}"] = n
    assert long == {}


def test_every_exception_is_explained_in_the_layout_page():
    page = LAYOUT.read_text(encoding="utf-8")
    assert [name for name in LONGER if f"`{name}`" not in page] == []
