"""MkDocs hooks of the docs site (``mkdocs build --strict``): names that can drift are taken
from the code, never typed twice.

* ``{{ readme }}`` (the home page): the README, its ``docs/`` links made relative to the site;
* ``{{ default_agent }}``, ``{{ suites }}``, ``{{ families }}``, ``{{ control_families }}``,
  ``{{ agents }}``: from :mod:`icrsumo.defaults`, the bundled suites, :mod:`icrsumo.vocab` and
  the agent registry. An unknown ``{{ name }}`` stops the build.
"""

from __future__ import annotations

import re
from pathlib import Path

_PLACEHOLDER = re.compile(r"\{\{ (\w+) \}\}")


def names() -> dict[str, str]:
    """Placeholder -> its text, from the code."""
    from icrsumo.agents.registry import DEFAULT_AGENT, REGISTRY
    from icrsumo.resources import bundled_suites
    from icrsumo.vocab import CONTROL_FAMILIES, FAMILIES

    def code(items) -> str:
        return ", ".join(f"`{x}`" for x in items)

    return {"default_agent": f"`{DEFAULT_AGENT}`", "suites": code(bundled_suites()),
            "families": code(FAMILIES), "control_families": code(CONTROL_FAMILIES), "agents": code(REGISTRY)}


def readme(root: Path) -> str:
    """The README as the site's home page: links into docs/ made relative, and the generated
    names block shown as it is."""
    text = (root / "README.md").read_text(encoding="utf-8")
    return text.replace("](docs/", "](")


def on_page_markdown(markdown: str, page, config, files) -> str:  # noqa: ARG001 - MkDocs' signature
    if "{{ readme }}" in markdown:
        markdown = markdown.replace("{{ readme }}", readme(Path(config["config_file_path"]).parent))
    known = names()

    def sub(m: re.Match) -> str:
        if m.group(1) not in known:
            raise ValueError(f"{page.file.src_path}: unknown placeholder {m.group(0)} "
                             f"(known: {', '.join(known)})")
        return known[m.group(1)]

    return _PLACEHOLDER.sub(sub, markdown)
