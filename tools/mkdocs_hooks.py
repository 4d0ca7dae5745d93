"""MkDocs hooks of the docs site (``mkdocs build --strict``).

* The home page (``docs/index.md``, which on a code host links to the README) is the README,
  its ``docs/`` links made relative to the site.
* No page may hold a template placeholder ``{{ ... }}``: the names that can drift are written
  into the pages by ``python tools/sync_names.py`` (checked by tests/test_docs.py), so every page
  reads the same on a code host as on the site. A placeholder stops the build.
"""

from __future__ import annotations

from pathlib import Path

HOME = "index.md"


def readme(root: Path) -> str:
    """The README as the site's home page: links into docs/ made relative, and the generated
    names block shown as it is."""
    text = (root / "README.md").read_text(encoding="utf-8")
    return text.replace("](docs/", "](")


def on_page_markdown(markdown: str, page, config, files) -> str:  # noqa: ARG001 - MkDocs' signature
    if page.file.src_path == HOME:
        return readme(Path(config["config_file_path"]).parent)
    if "{{" in markdown:
        raise ValueError(f"{page.file.src_path}: holds a template placeholder {{{{ ... }}}}: write the "
                         "text itself (names from the code: an inline span of tools/sync_names.py)")
    return markdown
