"""Agent identity without SUMO: fingerprints of file, module, learned and remote agents, and the
store refusing another agent's rows under the same name."""

from __future__ import annotations

import hashlib
import sys
import textwrap

import pytest

from icrsumo.agents.identity import fingerprint, short
from icrsumo.agents.registry import agent_factory, load_class
from icrsumo.agents.remote import RemoteFactory
from icrsumo.agents.serve import AgentServer
from icrsumo.errors import InputError
from icrsumo.learn.agent import CHECKPOINTS
from icrsumo.store import ResultStore
from icrsumo.types import EpisodeRecord
from icrsumo.vocab import EpisodeStatus

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


def test_learned_agents_are_their_checkpoints_and_builtins_differ():
    for name in ("bev-ngram-aug", "bev-ngram", "bev-token"):
        digest = hashlib.sha256((CHECKPOINTS / f"{name}.npz").read_bytes()).hexdigest()
        assert fingerprint(agent_factory(name)) == f"sha256:{digest}"
        assert fingerprint(agent_factory(name, device="cpu")) == f"sha256:{digest}"  # OnDevice
    assert fingerprint(agent_factory("route-oracle")) != fingerprint(agent_factory("instruction-follower"))


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
        assert "--replace-agent keyword" in line and "another --out" in line and "\n" not in line
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
