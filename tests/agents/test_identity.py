"""Agent identity without SUMO: fingerprints of file, module, learned and remote agents, and the
store refusing another agent's rows under the same name."""

from __future__ import annotations

import hashlib
import importlib
import shutil
import sys
import textwrap

import pytest

from icrsumo.agents.hosting.serve import AgentServer
from icrsumo.agents.identity import fingerprint, short
from icrsumo.agents.registry import agent_factory, load_class
from icrsumo.agents.remote import RemoteFactory
from icrsumo.core.errors import InputError
from icrsumo.core.types import EpisodeRecord
from icrsumo.core.vocab import EpisodeStatus
from icrsumo.learn.agent import CHECKPOINTS
from icrsumo.results.store import ResultStore

AGENT = '''
import numpy as np
from icrsumo.agents.base import Action
from helpers import SPEED

class Keyword:
    name = "keyword"
    privileged = False
    def reset(self, info):
        pass
    def act(self, obs):
        return Action(waypoints=np.array([[2.5, 0.0], [5.0, 0.0]]), target_speed=SPEED)

class Other(Keyword):
    pass
'''


def _write_agent(folder, speed=5.0, body=AGENT):
    folder.mkdir(exist_ok=True)
    (folder / "helpers.py").write_text(f"SPEED = {speed}\n")
    (folder / "agent.py").write_text(textwrap.dedent(body))
    return folder / "agent.py"


def _fp(path, cls="Keyword", monkeypatch=None):
    """The fingerprint of the class ``cls`` of the agent file ``path`` (imported as evaluate
    would, with its folder on the path for its helper)."""
    monkeypatch.syspath_prepend(str(path.parent))
    monkeypatch.delitem(sys.modules, "helpers", raising=False)
    return fingerprint(load_class(f"{path}:{cls}"))


def test_a_file_agent_changes_identity_with_its_file_and_its_helpers(tmp_path, monkeypatch):
    a = _fp(_write_agent(tmp_path / "a"), monkeypatch=monkeypatch)
    assert a.startswith("sha256:") and len(a) == 71
    assert _fp(_write_agent(tmp_path / "a2"), monkeypatch=monkeypatch) == a  # same bytes elsewhere
    edited = AGENT.replace("[5.0, 0.0]]", "[5.5, 0.0]]")
    assert _fp(_write_agent(tmp_path / "b", body=edited), monkeypatch=monkeypatch) != a  # its own file
    assert _fp(_write_agent(tmp_path / "c", speed=6.0), monkeypatch=monkeypatch) != a  # a helper beside it
    assert _fp(_write_agent(tmp_path / "a"), "Other", monkeypatch) != a  # another class of the file


def test_learned_agents_are_their_code_and_checkpoints_and_builtins_differ():
    fps = {name: fingerprint(agent_factory(name)) for name in ("bev-ngram-aug", "bev-ngram", "bev-token")}
    for name, fp in fps.items():
        digest = hashlib.sha256((CHECKPOINTS / f"{name}.npz").read_bytes()).hexdigest()
        assert fp.startswith("sha256:") and fp != f"sha256:{digest}"  # the code too, not the checkpoint alone
        assert fingerprint(agent_factory(name, device="cpu")) == fp  # OnDevice: the same agent
    assert len(set(fps.values())) == 3
    assert fingerprint(agent_factory("route-oracle")) != fingerprint(agent_factory("instruction-follower"))


# ---------------------------------------------------------------- what an agent reaches
#: agent packages on disk, one per way an agent reaches code: files (path -> text), the spec
#: (``{root}``: the folder put on the path), the file whose edit must change the fingerprint
#: and one whose edit must not
ACT = "    def reset(self, info):\n        pass\n"
CASES = {
    "dotted-import": ({
        "idt_a/__init__.py": "",
        "idt_a/agent.py": "import idt_a.util.speeds\n\nclass A:\n" + ACT +
                          "    def act(self, obs):\n        return idt_a.util.speeds.SPEED\n",
        "idt_a/util/__init__.py": "",
        "idt_a/util/speeds.py": "SPEED = 5.0\n",
        "idt_a/util/unused.py": "SPEED = 1.0\n",
    }, "idt_a.agent:A", "idt_a/util/speeds.py", "idt_a/util/unused.py"),
    "through-a-helper": ({
        "agent.py": "from idt_helper import GAIN\n\nclass B:\n" + ACT +
                         "    def act(self, obs):\n        return GAIN\n",
        "idt_helper.py": "from idt_deep import GAIN\n",
        "idt_deep.py": "GAIN = 2.0\n",
        "idt_other.py": "GAIN = 3.0\n",
    }, "{root}/agent.py:B", "idt_deep.py", "idt_other.py"),
    "sibling-package": ({
        "idt_c/__init__.py": "",
        "idt_c/agents/__init__.py": "",
        "idt_c/agents/mine/__init__.py": "",
        "idt_c/agents/mine/agent.py": "from ..policies import core\n\nclass C:\n" + ACT +
                                      "    def act(self, obs):\n        return core.decide(obs)\n",
        "idt_c/agents/policies/__init__.py": "",
        "idt_c/agents/policies/core.py": "def decide(obs):\n    return 1.0\n",
        "idt_c/agents/policies/other.py": "def decide(obs):\n    return 2.0\n",
    }, "idt_c.agents.mine.agent:C", "idt_c/agents/policies/core.py", "idt_c/agents/policies/other.py"),
    "sibling-folder-imported-in-a-function": ({
        "mine/agent.py": "class C2:\n" + ACT + "    def act(self, obs):\n        import idt_policies.core\n"
                         "        return idt_policies.core.decide(obs)\n",
        "idt_policies/__init__.py": "",
        "idt_policies/core.py": "def decide(obs):\n    return 1.0\n",
        "idt_policies/other.py": "def decide(obs):\n    return 2.0\n",
    }, "{root}/mine/agent.py:C2", "idt_policies/core.py", "idt_policies/other.py"),
    "class-with-a-checkpoint": ({
        "idt_d/__init__.py": "",
        "idt_d/agent.py": "from pathlib import Path\n\nclass D:\n"
                          "    checkpoint = str(Path(__file__).with_name('model.bin'))\n" + ACT +
                          "    def act(self, obs):\n        return 1.0\n",
        "idt_d/model.bin": "weights v1",
        "idt_d/notes.py": "X = 1\n",
    }, "idt_d.agent:D", "idt_d/agent.py", "idt_d/notes.py"),
}


def _forget_modules() -> None:
    """Drop the test packages' modules, so the next load imports them from where they are now."""
    for name in [m for m in sys.modules if m.startswith(("idt_", "mine"))]:
        del sys.modules[name]
    importlib.invalidate_caches()


def _case_fp(root, spec, monkeypatch) -> str:
    """The fingerprint of ``spec`` loaded from ``root`` as evaluate would (``root`` on the path)."""
    _forget_modules()
    monkeypatch.syspath_prepend(str(root))
    try:
        return fingerprint(agent_factory(spec.format(root=root)))
    finally:
        sys.path.remove(str(root))


@pytest.fixture()
def clean_modules(monkeypatch):
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    yield
    _forget_modules()


@pytest.mark.parametrize("case", list(CASES))
def test_the_fingerprint_covers_every_module_the_agent_reaches(case, tmp_path, monkeypatch, clean_modules):
    files, spec, reached, unrelated = CASES[case]
    root = tmp_path / "one"
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    before = _case_fp(root, spec, monkeypatch)
    shutil.copytree(root, tmp_path / "two")
    assert _case_fp(tmp_path / "two", spec, monkeypatch) == before  # the same agent in another folder
    (root / unrelated).write_text((root / unrelated).read_text() + "# edited\n")
    assert _case_fp(root, spec, monkeypatch) == before  # a file the agent does not reach
    (root / reached).write_text((root / reached).read_text().replace("1.0", "1.5").replace("2.0", "2.5")
                                .replace("5.0", "5.5"))
    assert _case_fp(root, spec, monkeypatch) != before  # a file it reaches


def test_a_checkpointed_agent_is_its_checkpoint_too(tmp_path, monkeypatch, clean_modules):
    files, spec, _, _ = CASES["class-with-a-checkpoint"]
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    before = _case_fp(tmp_path, spec, monkeypatch)
    (tmp_path / "idt_d/model.bin").write_text("weights v2")
    assert _case_fp(tmp_path, spec, monkeypatch) != before


def test_a_declared_fingerprint_wins():
    class Declared:
        fingerprint = "my-model v3, weights 5f2a"

    other = type("Declared", (), {"fingerprint": "my-model v4"})
    assert fingerprint(Declared) == fingerprint(type("X", (), {"fingerprint": "my-model v3, weights 5f2a"}))
    assert fingerprint(Declared) != fingerprint(other)


def test_a_remote_agent_is_what_its_server_reports():
    server = AgentServer("bev-ngram-aug").start()
    try:
        remote = RemoteFactory(server.url)
        assert remote.info["fingerprint"] == fingerprint(agent_factory("bev-ngram-aug"))
        assert fingerprint(remote) == remote.info["fingerprint"]
    finally:
        server.shutdown()


def _rec(agent, k=0):
    return EpisodeRecord(agent=agent, route_id="r1", family="baseline", k=k, seed=1,
                         status=EpisodeStatus.DONE, ds=100.0, rc=100.0, is_=1.0)


def test_the_store_refuses_another_agent_of_the_same_name(tmp_path):
    path = tmp_path / "results.sqlite"
    old, new = "sha256:" + "a" * 64, "sha256:" + "b" * 64
    with ResultStore(path) as store:
        store.claim_agents({"keyword": old})
        store.put(_rec("keyword"))
        store.put(_rec("keyword", 1))
        assert store.agent_fingerprints() == {"keyword": {old}}
        assert store.check_agents({"keyword": old}) == []  # the same agent resumes
        with pytest.raises(InputError) as err:
            store.check_agents({"keyword": new})
        line = str(err.value)
        assert "agent keyword" in line and short(old) in line and short(new) in line
        assert "replace_agents keyword" in line and "another out folder" in line and "\n" not in line
        # replacing: the other agent's rows go, rows of the new one (a resumed replacing run) stay
        store.claim_agents({"keyword": new}, replace=("keyword",))
        assert store.keys() == set()
        store.put(_rec("keyword"))
        store.claim_agents({"keyword": new}, replace=("keyword",))
        assert len(store.keys()) == 1 and store.agent_fingerprints() == {"keyword": {new}}


def test_rows_stored_before_fingerprints_are_taken_as_the_agents(tmp_path):
    path = tmp_path / "results.sqlite"
    with ResultStore(path) as store:
        store.put(_rec("keyword"))  # no claim: an episode without a fingerprint
        assert store.check_agents({"keyword": "sha256:" + "c" * 64}) == ["keyword"]
        assert store.claim_agents({"keyword": "sha256:" + "c" * 64}, replace=("keyword",)) == []
        assert store.keys() == set()


class Tuned:
    """An agent whose settings live on the instance."""

    name = "tuned"
    privileged = False

    def __init__(self, gain: float, fingerprint: str | None = None) -> None:
        self.gain = gain
        if fingerprint:
            self.fingerprint = fingerprint

    def reset(self, info):
        pass

    def act(self, obs):
        return None


def test_instances_are_known_by_their_settings_and_their_own_fingerprint():
    from icrsumo.agents.registry import InstanceFactory

    assert fingerprint(InstanceFactory(Tuned(1.0))) == fingerprint(InstanceFactory(Tuned(1.0)))
    assert fingerprint(InstanceFactory(Tuned(1.0))) != fingerprint(InstanceFactory(Tuned(2.0)))
    assert fingerprint(InstanceFactory(Tuned(1.0, "v1"))) != fingerprint(InstanceFactory(Tuned(1.0, "v2")))


def test_settings_bound_into_a_factory_function_count():
    import functools

    from icrsumo.agents.registry import python_agent

    def fp(gain):
        return fingerprint(python_agent(functools.partial(Tuned, gain))[1])

    assert fp(1.0) == fp(1.0) and fp(1.0) != fp(2.0)


def test_an_instance_of_a_path_agent_is_the_same_agent_from_another_folder(tmp_path, monkeypatch,
                                                                           clean_modules):
    from icrsumo.agents.registry import InstanceFactory

    fps = []
    for folder in (tmp_path / "one", tmp_path / "two"):  # module names differ: they hash the path
        _write_agent(folder)
        fps.append(fingerprint(InstanceFactory(_load(folder / "agent.py", monkeypatch)())))
    assert fps[0] == fps[1]


def _load(path, monkeypatch, cls="Keyword"):
    monkeypatch.syspath_prepend(str(path.parent))
    monkeypatch.delitem(sys.modules, "helpers", raising=False)
    return load_class(f"{path}:{cls}")


def test_installed_code_is_known_by_its_distribution_not_read(tmp_path, monkeypatch, clean_modules):
    from importlib.metadata import version

    from icrsumo.agents.identity import _code

    (tmp_path / "agent.py").write_text(
        "import json\nimport numpy as np\nfrom numpy.lib.mixins import NDArrayOperatorsMixin\n\n"
        "class E(NDArrayOperatorsMixin):\n    def act(self, obs):\n        return np.zeros(2)\n")
    cls = _load(tmp_path / "agent.py", monkeypatch, "E")
    keys = [key for key, _ in _code(cls.__mro__)]
    assert keys == ["agent.py", f"installed numpy=={version('numpy')}"]  # a base class installed: its version


WORDS = """
class Words:
    name = "words"
    def __init__(self):
        self.stop = {"stop", "halt", "wait", "hold"}
    def reset(self, info):
        pass
    def act(self, obs):
        return None
"""


def test_an_instance_with_a_set_has_one_fingerprint_whatever_the_hash_seed(tmp_path):
    import os
    import subprocess

    (tmp_path / "idt_words.py").write_text(WORDS)
    code = ("from icrsumo.agents.identity import fingerprint\n"
            "from icrsumo.agents.registry import InstanceFactory\n"
            "from idt_words import Words\nprint(fingerprint(InstanceFactory(Words())))")
    fps = set()
    for seed in ("1", "2", "3"):  # a set of strings iterates in the hash seed's order
        env = {**os.environ, "PYTHONHASHSEED": seed, "PYTHONPATH": str(tmp_path)}
        fps.add(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                               timeout=120, cwd=tmp_path, env=env).stdout)
    assert len(fps) == 1
