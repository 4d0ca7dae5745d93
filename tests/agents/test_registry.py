"""The agent registry (explicit registration, duplicates refused), agent specs with a device,
the transport-free BatchingCore, and the import structure of the agents package."""

from __future__ import annotations

import ast
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import icrsumo.agents as agents_pkg
from icrsumo.agents.base import Action, EpisodeInfo, Observation, batch_hook
from icrsumo.agents.hosting.batching import BatchingCore, Task
from icrsumo.agents.privileged import InstructionFollower, RouteOracle
from icrsumo.agents.registry import (
    BUILTIN,
    DEFAULT_AGENT,
    REGISTRY,
    OnDevice,
    agent_factory,
    agent_name,
    make_agent,
    register,
    unregister,
)
from icrsumo.core.errors import InputError
from icrsumo.learn.agent import CHECKPOINTS, LearnedAgent

AGENTS_DIR = Path(agents_pkg.__file__).parent
INFO = EpisodeInfo("r", "town", "net.xml", 0.05, 0.1, 7)
OBS = Observation(0.0, np.zeros((7, 4, 4), np.uint8), 2.0, "Turn left.", 0, "")


class Echo:
    """A minimal non-privileged agent: its target speed is the observed speed plus its calls."""

    name = "echo"
    privileged = False

    def reset(self, info: EpisodeInfo) -> None:
        self.calls = 0

    def act(self, obs: Observation) -> Action:
        self.calls += 1
        return Action(waypoints=np.array([[1.0, 0.0]]), target_speed=obs.speed + self.calls)


@pytest.fixture
def echo():
    """``echo`` registered for one test."""
    register("echo", Echo, description="test agent")
    yield "echo"
    unregister("echo")


def test_the_built_ins_are_registered():
    assert BUILTIN is REGISTRY
    assert REGISTRY["route-oracle"] is RouteOracle and REGISTRY["instruction-follower"] is InstructionFollower
    learned = {"bev-token", "bev-ngram", "bev-ngram-aug", "bev-minilm", "bev-minilm-aug"}
    shipped = {n for n in learned if (CHECKPOINTS / f"{n}.npz").is_file()}
    assert set(REGISTRY) == {"route-oracle", "instruction-follower"} | shipped
    assert DEFAULT_AGENT in REGISTRY
    assert REGISTRY.entry("route-oracle").description


def test_a_duplicate_name_is_refused(echo):
    with pytest.raises(ValueError, match="agent 'echo' is already registered .*Echo.*unregister"):
        register("echo", Echo)
    with pytest.raises(ValueError, match="'route-oracle' is already registered"):
        register("route-oracle", Echo)
    assert REGISTRY["route-oracle"] is RouteOracle  # untouched


@pytest.mark.parametrize("name", ["", "a b", "remote:x", "mod:Cls"])
def test_names_that_are_not_specs_are_refused(name):
    with pytest.raises(ValueError, match="is not valid"):
        register(name, Echo)
    assert name not in REGISTRY


def test_a_factory_must_be_callable():
    with pytest.raises(TypeError, match="not callable"):
        register("not-callable", 42)  # type: ignore[arg-type]


def test_registered_agents_resolve_like_built_ins(echo):
    assert agent_factory("echo") is Echo
    agent = make_agent("echo")
    assert isinstance(agent, Echo) and agent_name("echo", agent) == "echo"
    unregister("echo")
    with pytest.raises(InputError, match="not a built-in agent"):
        agent_factory("echo")
    with pytest.raises(KeyError, match="'echo' is not registered"):
        unregister("echo")
    register("echo", Echo)  # for the fixture's teardown


def test_a_device_reaches_the_learned_agents_only():
    name = next(n for n, f in REGISTRY.items() if isinstance(f, type) and issubclass(f, LearnedAgent))
    factory = agent_factory(name, device="cpu")
    assert isinstance(factory, OnDevice) and factory.device == "cpu"
    assert (factory.name, factory.privileged) == (name, False)
    assert batch_hook(factory) is not None  # act_batch is found through agent_class
    agent = factory()
    assert isinstance(agent, LearnedAgent) and agent.device == "cpu"
    assert pickle.loads(pickle.dumps(factory)) == factory
    assert agent_factory(name) is REGISTRY[name]  # no device: the class itself
    assert agent_factory("route-oracle", device="cuda") is RouteOracle  # takes no device: unchanged


def test_batching_core_runs_a_factory_without_transport():
    core = BatchingCore(Echo, max_batch=2)
    assert core.name == "echo" and not core.batch_hook
    resets = [Task("reset", s, INFO) for s in ("a", "b")]
    core.run(resets)
    acts = [Task("act", s, OBS) for s in ("a", "b", "a", "zz")]
    core.run(acts)
    assert [t.status for t in resets] == [200, 200] and all(t.done.is_set() for t in acts)
    assert [t.result.target_speed if t.status == 200 else t.status for t in acts] == [3.0, 3.0, 4.0, 404]
    assert core.stats == {"resets": 2, "acts": 3, "batches": 2, "largest_batch": 2}
    close = Task("close", "a")
    core.run([close])
    assert close.status == 200 and list(core.sessions) == ["b"]
    with pytest.raises(InputError, match="must be at least 1"):
        BatchingCore(Echo, max_batch=0)


def _imports(path: Path) -> set[str]:
    """Every module a file imports, anywhere in it (relative ones as written: '.batched')."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            names.add("." * node.level + (node.module or ""))
            if not node.module:
                names.update("." * node.level + a.name for a in node.names)
    return names


def test_no_import_cycle_between_registry_and_transports():
    registry = _imports(AGENTS_DIR / "registry.py")
    assert not any("batched" in m or "serve" in m for m in registry), registry
    batching = _imports(AGENTS_DIR / "hosting" / "batching.py")
    assert not any(m.endswith(("registry", "serve", "batched", "remote")) for m in batching), batching
    code = ("import sys, icrsumo.agents.registry; "
            "print(sorted(m for m in sys.modules if m.startswith('icrsumo.agents.')))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "batched" not in loaded and "serve" not in loaded and "batching" not in loaded


def test_no_process_state_in_environment_or_module_globals():
    for module in ("hosting/batched.py", "registry.py", "hosting/serve.py", "hosting/batching.py"):
        text = (AGENTS_DIR / module).read_text(encoding="utf-8")
        assert "os.environ" not in text and "LAST_STATS" not in text and "_CONNS" not in text, module
    learned = (AGENTS_DIR.parent / "learn" / "agent.py").read_text(encoding="utf-8")
    assert "os.environ" not in learned and "DEVICE_ENV" not in learned
