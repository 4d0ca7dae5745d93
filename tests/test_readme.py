"""The README's Python API example runs as it is written (real SUMO, real agents)."""

from __future__ import annotations

import contextlib
import io
import os
import re
from pathlib import Path

import pytest

pytestmark = pytest.mark.sumo

README = Path(__file__).resolve().parents[1] / "README.md"


def _api_example() -> str:
    text = README.read_text(encoding="utf-8")
    m = re.search(r"<!-- api-example -->\n```python\n(.*?)```", text, re.S)
    assert m, "README: the Python API example block (after <!-- api-example -->) is missing"
    return m.group(1)


def test_the_python_api_example_runs(tmp_path):
    code = _api_example()
    ns: dict = {"__name__": "readme_example"}
    out = io.StringIO()
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        with contextlib.redirect_stdout(out):
            exec(compile(code, str(README), "exec"), ns)  # noqa: S102 - the README's own code
    finally:
        os.chdir(cwd)
    lines = out.getvalue().splitlines()
    assert len(lines) == 3
    assert lines[1] == "8 0"  # the comment in the README
    log, result, run = ns["log"], ns["result"], ns["run"]
    assert log.route_id == "tiny_003" and log.family == "misleading" and len(log.t) > 10
    assert lines[0].split()[1:3] == [str(result.termination), str(result.termination_class)]
    assert ns["junctions"].steps > 0
    assert (tmp_path / "icr_out" / "summary.json").is_file() and run.out == Path("icr_out")
    assert set(run.summary["agents"]) == {"route-oracle", "instruction-follower"}
