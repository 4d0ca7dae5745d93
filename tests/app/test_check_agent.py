"""``icrsumo check-agent``: its findings on users' agents, in plain words, and bad input."""

from __future__ import annotations

from pathlib import Path

import pytest

from icrsumo.app.cli.main import main

pytestmark = pytest.mark.sumo

AGENTS = Path(__file__).parents[1] / "data" / "agents" / "user_agents.py"


@pytest.mark.parametrize("cls, code, expect", [
    ("Cruise", 0, ["the agent follows the protocol", "deterministic"]),
    ("BevKeeper", 0, ["act_batch() matches act()"]),
    ("NoAct", 1, ["missing method act()"]),
    ("NoName", 1, ["no `name` attribute", "no `privileged` attribute"]),
    ("NaNs", 1, ["act() at decision 1", "waypoints contain NaN"]),
    ("WrongShape", 1, ["waypoints must have shape (N, 2) with N >= 1, got (3,)"]),
    ("ReturnsDict", 1, ["act() returned dict, expected icrsumo.agents.base.Action"]),
    ("Raises", 1, ["act() at decision 3", "raised RuntimeError: agent exploded at user_agents.py:"]),
    ("NonDeterministic", 1, ["not deterministic: two runs with the same seed differ at decision 1"]),
    ("Hangs", 1, ["act() at decision 3", "did not answer within 1 s"]),
    ("Slow", 1, ["too slow: act() takes 1"]),
])
def test_check_agent_reports_in_plain_words(cache, capsys, cls, code, expect):
    argv = ["check-agent", f"{AGENTS}:{cls}", "--timeout", "1", "--decisions", "30", "--max-act-ms", "50"]
    if cls == "Slow":
        argv[-3:-2] = ["4"]
    assert main(argv) == code
    out = capsys.readouterr().out
    for text in expect:
        assert text in out, out
    assert ("PROBLEM" in out) == (code == 1)


@pytest.mark.parametrize("spec, expect", [
    ("no_such_module_xyz:Agent", "cannot import no_such_module_xyz"),
    ("missing/file.py:Agent", "agent file not found"),
    (f"{AGENTS}:Nope", "has no attribute Nope"),
])
def test_check_agent_bad_input_is_exit_2(cache, capsys, spec, expect):
    assert main(["check-agent", spec]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expect in err[0] and "Traceback" not in err[0]


def test_check_agent_says_whether_an_agent_is_cpu_independent(cache, capsys, tmp_path):
    """One line: an exact checkpoint proven against its int64 reference on the run's
    observations, a float checkpoint not CPU-independent, other agents not checked."""
    from icrsumo.learn.agent import CHECKPOINTS

    assert main(["check-agent", "bev-ngram-aug", "--decisions", "20"]) == 0
    out = capsys.readouterr().out
    assert "CPU-independent: exact checkpoint, its fast path equals the int64 reference bit for bit" in out
    floats = tmp_path / "float_agent.py"
    floats.write_text("from icrsumo.learn.agent import LearnedAgent\n\n\nclass Float(LearnedAgent):\n"
                      f"    name = 'float'\n    checkpoint = {str(CHECKPOINTS / 'bev-ngram-aug.pt')!r}\n")
    assert main(["check-agent", f"{floats}:Float", "--decisions", "20"]) == 0
    assert "not CPU-independent: a float checkpoint's actions depend on the CPU" in capsys.readouterr().out
    assert main(["check-agent", f"{AGENTS}:Cruise", "--decisions", "20"]) == 0
    assert "CPU independence not checked" in capsys.readouterr().out
