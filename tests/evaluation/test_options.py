"""Without SUMO: option checks (no user code imported), the lazy Python API, the progress bar
quiet and not, and the package layout (no icrsumo/evaluate.py module)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import icrsumo
from icrsumo.core.errors import InputError
from icrsumo.evaluation import EvalOptions
from icrsumo.evaluation.progress import Progress

AGENTS = Path(__file__).parents[1] / "data" / "agents" / "user_agents.py"


@pytest.mark.parametrize("kw, expect", [
    (dict(families=("sarcasm",)), "unknown family"),
    (dict(backend="slurm"), "unknown backend"),
    (dict(k=0), "out of range"),
    (dict(workers=0), "must be at least 1"),
    (dict(agent_timeout=0.0), "must be positive"),
    (dict(batch_inference="cpu", backend="ray"), "local backend only"),
    (dict(batch_inference="cpu", max_batch=0), "must be at least 1"),
    (dict(suite="huge"), "unknown suite"),
])
def test_bad_options_are_input_errors(tmp_path, kw, expect):
    with pytest.raises(InputError, match=expect):
        EvalOptions(out=tmp_path, **kw).check()


def test_checking_options_imports_no_user_code(tmp_path):
    """Specs are resolved by the orchestration, once: check() does not even look at them."""
    EvalOptions(out=tmp_path, agents=("no_such_module_xyz:Agent", f"{AGENTS}:NoAct")).check()
    assert "no_such_module_xyz" not in sys.modules


def test_the_api_is_exported_lazily():
    """``import icrsumo`` loads nothing of the package but the old-names table (standard library
    only); the API comes on first use."""
    code = ("import sys, icrsumo; loaded = sorted(m for m in sys.modules if m.startswith('icrsumo.')); "
            "assert loaded == ['icrsumo.compat'], loaded; "
            "from icrsumo import evaluate, load_suite, Suite, EvalResult; "
            "import icrsumo.app.api as api; assert evaluate is api.evaluate and load_suite is api.load_suite")
    subprocess.run([sys.executable, "-c", code], check=True)
    assert {"evaluate", "load_suite"} <= set(dir(icrsumo))
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        icrsumo.nope  # noqa: B018
    assert not (Path(icrsumo.__file__).parent / "evaluate.py").exists()


def test_unknown_api_options_are_type_errors(tmp_path):
    with pytest.raises(TypeError, match="unknown evaluation option 'kk'.*max_batch"):
        icrsumo.evaluate(out=tmp_path, kk=3)
    with pytest.raises(InputError, match="unknown family"):
        icrsumo.evaluate(out=tmp_path / "o", families="sarcasm")
    with pytest.raises(InputError, match="not a built-in agent"):
        icrsumo.evaluate(out=tmp_path / "o", agents="no-such-agent")
    assert not (tmp_path / "o").exists()


def test_progress_quiet_prints_nothing(capsys):
    with Progress(3, quiet=True) as p:
        for _ in range(3):
            p.tick()
    assert p.done == 3
    assert capsys.readouterr() == ("", "")


def test_progress_not_quiet_counts_episodes_on_stderr(capsys):
    with Progress(20, quiet=False) as p:
        for _ in range(20):
            p.tick()
    out, err = capsys.readouterr()
    assert out == ""
    assert "20/20" in err and "episode" in err and "icrsumo" in err
    assert err.count("\r") <= 14  # not a terminal: about one update per 10 % (and the ends)


def test_progress_of_nothing_prints_nothing(capsys):
    with Progress(0, quiet=False):
        pass
    assert capsys.readouterr() == ("", "")


@pytest.mark.parametrize(("kw", "line"), [
    ({"k": "1"}, "k: '1': must be an integer, not str"),
    ({"workers": "2"}, "workers: '2': must be an integer, not str"),
    ({"seed": 1.5}, "seed: 1.5: must be an integer, not float"),
    ({"quiet": "yes"}, "quiet: 'yes': must be True or False"),
    ({"agent_timeout": "60"}, "agent_timeout: '60': must be a number of seconds or None"),
])
def test_the_python_api_names_a_value_of_the_wrong_type(tmp_path, kw, line):
    import icrsumo
    from icrsumo.core.errors import InputError

    with pytest.raises(InputError) as err:
        icrsumo.evaluate(out=tmp_path / "o", **kw)
    assert line in str(err.value) and not (tmp_path / "o").exists()
