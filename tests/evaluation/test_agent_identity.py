"""Results belong to the agent that produced them: an edited agent under the same name (its file,
or a module it reaches through a helper) is refused (one line, exit 2, nothing touched),
replaced on request, and two agents of one name in one run are refused."""

from __future__ import annotations

import json
import sqlite3
import sys

import pytest

from icrsumo.agents.identity import short
from icrsumo.app.cli.main import main

pytestmark = pytest.mark.sumo

AGENT = '''
import numpy as np
from icrsumo.agents.base import Action
from idt_kw_helper import GAP

class Keyword:
    name = "keyword"
    privileged = False
    def reset(self, info):
        pass
    def act(self, obs):
        speed = 3.0 if "stop" in obs.instruction.lower() else SPEED
        return Action(waypoints=np.array([[GAP, 0.0], [5.0, 0.0], [7.5, 0.0]]), target_speed=speed)

SPEED = {speed}
'''
RUN = ["evaluate", "--suite", "tiny", "--routes", "tiny_003", "--family", "misleading", "--k", "1",
       "--workers", "1", "--quiet"]


@pytest.fixture(autouse=True)
def _helpers_importable(tmp_path, monkeypatch):
    """The agent's helper modules (written beside it) importable, and forgotten afterwards."""
    monkeypatch.syspath_prepend(str(tmp_path))
    yield
    for name in [m for m in sys.modules if m.startswith("idt_kw_")]:
        del sys.modules[name]


def _agent(path, speed):
    """An agent file that reaches a module through a helper (agent -> helper -> deep)."""
    path.write_text(AGENT.format(speed=speed))
    (path.parent / "idt_kw_helper.py").write_text("from idt_kw_deep import GAP\n")
    if not (path.parent / "idt_kw_deep.py").exists():
        (path.parent / "idt_kw_deep.py").write_text("GAP = 2.5\n")
    return f"{path}:Keyword"


def _rows(out):
    db = sqlite3.connect(out / "results.sqlite")
    try:
        return sorted(db.execute("SELECT agent, family, k, ds, fingerprint FROM episodes"))
    finally:
        db.close()


def test_an_edited_agent_is_refused_then_replaced_on_request(tmp_path, capsys):
    out, agent = tmp_path / "out", tmp_path / "keyword.py"
    spec = _agent(agent, 5.0)
    assert main([*RUN, "--agent", spec, "--out", str(out)]) == 0
    first = _rows(out)
    fp = json.loads((out / "config.json").read_text())["agents"]["keyword"]["fingerprint"]
    assert len(first) == 2 and {r[4] for r in first} == {fp}
    assert json.loads((out / "config.json").read_text())["agents"]["keyword"]["spec"] == f"{agent}:Keyword"
    assert main([*RUN, "--agent", spec, "--out", str(out)]) == 0  # the same agent: resumed, nothing run
    assert "0 crashed" in capsys.readouterr().err and _rows(out) == first

    _agent(agent, 6.0)  # edited, same name
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert main([*RUN, "--agent", spec, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "agent keyword" in err[0] and short(fp) in err[0]
    assert "--replace-agent keyword" in err[0] and "Traceback" not in err[0]
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before

    assert main([*RUN, "--agent", spec, "--out", str(out), "--replace-agent", "keyword"]) == 0
    now = _rows(out)
    new_fp = json.loads((out / "config.json").read_text())["agents"]["keyword"]["fingerprint"]
    said = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("icrsumo: replacing")]
    assert said == [f"icrsumo: replacing keyword (now {short(new_fp)}): deleted 2 stored episodes of the "
                    f"agent of fingerprint {short(fp)}"]
    assert new_fp != fp and {r[4] for r in now} == {new_fp} and len(now) == 2
    assert now != first  # driven again by the edited agent (another speed, another episode)

    (tmp_path / "idt_kw_deep.py").write_text("GAP = 3.0\n")  # a module reached through a helper
    capsys.readouterr()
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert main([*RUN, "--agent", spec, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and short(new_fp) in err[0]
    assert "holds episodes of another agent of that name" in err[0]
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_two_agents_of_one_name_in_one_run_are_refused(tmp_path, capsys):
    a, b = _agent(tmp_path / "a.py", 5.0), _agent(tmp_path / "b.py", 6.0)
    out = tmp_path / "out"
    assert main([*RUN, "--agent", a, "--agent", b, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is named 'keyword'" in err[0] and not out.exists()
