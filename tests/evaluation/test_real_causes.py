"""Errors that name the real cause: a suite whose routes all fail to convert says why (a route id
too long, two ids that map to one folder name), not that no converted scenario was found."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from icrsumo.core.resources import bundled_suites

pytestmark = pytest.mark.sumo


def _suite(tmp_path, ids):
    text = bundled_suites()["tiny"].read_text()
    routes = re.findall(r'(<route id="[^"]+".*?</route>)', text, re.S)
    body = "\n".join(re.sub(r'id="[^"]+"', f'id="{rid}"', r, count=1) for rid, r in zip(ids, routes))
    path = tmp_path / "routes.xml"
    path.write_text(text[: text.index("<route ")] + body + "\n</routes>\n")
    return path


@pytest.mark.parametrize(("ids", "why"), [
    (["a" * 300], "route id is 300 characters long (fix: use an id of at most 200)"),
    (["x/1", "x_1"], "route id maps to the same folder name as another route"),
])
def test_evaluate_names_why_no_route_could_be_converted(tmp_path, ids, why):
    out = tmp_path / "o"
    cmd = [sys.executable, "-m", "icrsumo", "evaluate", "--suite", str(_suite(tmp_path, ids)), "--agent",
           "instruction-follower", "--family", "paraphrase", "--k", "1", "--out", str(out), "--quiet"]
    p = subprocess.run(cmd, capture_output=True, text=True)
    assert p.returncode == 2 and why in p.stderr and "no converted scenarios" not in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and not out.exists()
