"""The documentation: the README stays a newcomer's page whose names come from the code, and the
docs site builds with MkDocs with every warning an error (broken links and anchors included)."""

from __future__ import annotations

import argparse
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _sync_names():
    spec = importlib.util.spec_from_file_location("sync_names", ROOT / "tools" / "sync_names.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_readme_is_short_and_its_names_come_from_the_code():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) < 300, "the README is a newcomer's page: move measurements to docs/"
    assert _sync_names().synced(text) == text, "run python tools/sync_names.py"
    for target in re.findall(r"\]\((docs/[^)#]+)", text):
        assert (ROOT / target).is_file(), target


def test_the_docs_site_builds_strictly(tmp_path):
    argv = [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")]
    run = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    home = (tmp_path / "site" / "index.html").read_text(encoding="utf-8")
    from icrsumo.agents.registry import DEFAULT_AGENT

    assert "Bring your own agent" in home and DEFAULT_AGENT in home
    api = (tmp_path / "site" / "api" / "index.html").read_text(encoding="utf-8")
    assert "{{" not in api and f"<code>{DEFAULT_AGENT}</code>" in api  # the placeholder, filled from the code


def test_every_page_reads_right_on_a_code_host_and_its_names_come_from_the_code():
    """No template placeholder (a code host shows it raw); the inline generated names are current."""
    sync = _sync_names()
    for page in sorted((ROOT / "docs").glob("*.md")):
        text = page.read_text(encoding="utf-8")
        assert "{{" not in text, f"{page.name}: write the text itself (tools/sync_names.py for names)"
        assert sync.synced_page(text) == text, f"{page.name}: run python tools/sync_names.py"
    assert "<!-- names:default_agent -->" in (ROOT / "docs" / "api.md").read_text(encoding="utf-8")


def test_the_evaluate_synopsis_names_every_option():
    from icrsumo.app.cli.main import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    flags = {o for a in sub.choices["evaluate"]._actions for o in a.option_strings if o.startswith("--")}
    page = (ROOT / "docs" / "evaluate.md").read_text(encoding="utf-8")
    synopsis = page.split("```")[1]
    missing = sorted(f for f in flags - {"--help"} if not re.search(re.escape(f) + r"(?![\w-])", synopsis))
    assert not missing, f"docs/evaluate.md's synopsis lacks {missing}"


def test_every_developer_tool_is_listed():
    """docs/development.md's table names every script in tools/ (what it does, who runs it)."""
    page = (ROOT / "docs" / "development.md").read_text(encoding="utf-8")
    table = page.split("## Developer tools", 1)[1]
    missing = sorted(p.name for p in (ROOT / "tools").iterdir()
                     if p.suffix in (".py", ".sh") and f"`{p.name}`" not in table)
    assert missing == []
