"""Agents as plugins: a package that declares an agent in the ``icrsumo.agents`` entry-point
group, installed with pip into the test environment, is an agent name like the built-ins; the
registry imports no agent module (built-in or plugin) until that agent is asked for."""

from __future__ import annotations

import base64
import hashlib
import os
import subprocess
import sys
import zipfile

import pytest

PLUGIN = '''
import numpy as np
from icrsumo.agents.base import Action


class Cruise:
    """Drives straight on at 4 m/s."""

    name = "plugin-cruise"
    privileged = False

    def reset(self, info):
        pass

    def act(self, obs):
        return Action(waypoints=np.array([[2.0, 0.0], [4.0, 0.0]]), target_speed=4.0)
'''
FILES = {
    "icrsumo_test_plugin/__init__.py": PLUGIN,
    "icrsumo_test_plugin-0.1.dist-info/METADATA": "Metadata-Version: 2.1\nName: icrsumo-test-plugin\n"
                                                  "Version: 0.1\n",
    "icrsumo_test_plugin-0.1.dist-info/WHEEL": "Wheel-Version: 1.0\nGenerator: icrsumo-tests\n"
                                                "Root-Is-Purelib: true\nTag: py3-none-any\n",
    "icrsumo_test_plugin-0.1.dist-info/entry_points.txt": "[icrsumo.agents]\n"
                                                          "plugin-cruise = icrsumo_test_plugin:Cruise\n",
}


def _wheel(folder):
    """A real wheel of the plugin package (its RECORD with the files' hashes)."""
    path = folder / "icrsumo_test_plugin-0.1-py3-none-any.whl"
    record = []
    with zipfile.ZipFile(path, "w") as z:
        for name, text in FILES.items():
            data = text.encode()
            z.writestr(name, data)
            digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
            record.append(f"{name},sha256={digest},{len(data)}")
        record.append("icrsumo_test_plugin-0.1.dist-info/RECORD,,")
        z.writestr("icrsumo_test_plugin-0.1.dist-info/RECORD", "\n".join(record) + "\n")
    return path


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The plugin installed by pip into a folder put on the path of the subprocesses."""
    tmp = tmp_path_factory.mktemp("plugin")
    target = tmp / "site"
    argv = [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-index",
            "--target", str(target), str(_wheel(tmp))]
    run = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    return target


def _python(site, code_or_args, module=False):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    argv = [sys.executable, "-m", *code_or_args] if module else [sys.executable, "-c", code_or_args]
    return subprocess.run(argv, capture_output=True, text=True, env=env, timeout=300)


def test_the_registry_imports_agents_only_when_asked(site):
    run = _python(site, """
import sys
from icrsumo.agents.registry import REGISTRY
assert "plugin-cruise" in REGISTRY and REGISTRY.entry("plugin-cruise").plugin == "icrsumo-test-plugin"
for mod in ("icrsumo_test_plugin", "icrsumo.agents.privileged", "icrsumo.learn.agent", "icrsumo.sim.episode"):
    assert mod not in sys.modules, mod
cls = REGISTRY["plugin-cruise"]
assert cls.__module__ == "icrsumo_test_plugin" and "icrsumo_test_plugin" in sys.modules
assert "icrsumo.agents.privileged" not in sys.modules
REGISTRY["route-oracle"]
assert "icrsumo.agents.privileged" in sys.modules
print("ok")
""")
    assert run.returncode == 0 and run.stdout.strip() == "ok", run.stderr


def test_list_shows_the_plugin(site):
    run = _python(site, ["icrsumo", "list", "agents"], module=True)
    assert run.returncode == 0, run.stderr
    assert any(line.split()[:2] == ["plugin-cruise", "plugin"] for line in run.stdout.splitlines())


@pytest.mark.sumo
def test_an_installed_plugin_agent_is_evaluated_by_name(site, tmp_path):
    out = tmp_path / "out"
    run = _python(site, ["icrsumo", "evaluate", "--suite", "tiny", "--routes", "tiny_003", "--agent",
                         "plugin-cruise", "--family", "misleading", "--k", "1", "--workers", "1", "--quiet",
                         "--out", str(out)], module=True)
    assert run.returncode == 0, run.stderr
    assert "2 episodes done, 0 crashed" in run.stderr
    assert "plugin-cruise" in (out / "results.md").read_text(encoding="utf-8")


@pytest.mark.parametrize("group, option", [("icrsumo.agents", "--agent"), ("icrsumo.guards", "--guard")])
def test_a_plugin_whose_import_exits_is_one_line_naming_it(tmp_path, group, option):
    """A plugin module that calls ``sys.exit(0)`` when imported is refused in one line naming
    the entry and the distribution (exit status 2), before anything runs: never a run that ends
    with status 0 having run nothing."""
    (tmp_path / "exiting_plugin.py").write_text("import sys\nsys.exit(0)\n")
    dist = tmp_path / "exiting_plugin-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: exiting-plugin\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(f"[{group}]\nexiting = exiting_plugin:Thing\n")
    out = tmp_path / "out"
    run = _python(tmp_path, ["icrsumo", "evaluate", option, "exiting", "--routes", "tiny_003", "--k", "1",
                             "--quiet", "--out", str(out)], module=True)
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and len(lines) == 1 and "Traceback" not in run.stderr, run.stderr
    assert f"{option}: exiting: cannot load exiting_plugin:Thing (plugin of exiting-plugin)" in lines[0]
    assert "its import called sys.exit(0)" in lines[0] and not out.exists()
