"""Shipped checkpoints: small, safe to load, deterministic, and drive in real SUMO. The agents
run the exact checkpoints (NAME.npz); the float ones they were made from (NAME.pt) ship beside
them."""

import numpy as np
import pytest
import torch

from icrsumo.agents.base import EpisodeInfo, Observation
from icrsumo.agents.registry import BUILTIN, make_agent
from icrsumo.learn.agent import CHECKPOINTS, LearnedAgent, act_batch

pytestmark = pytest.mark.sumo

SHIPPED = sorted(p.stem for p in CHECKPOINTS.glob("*.npz"))
LEARNED = [n for n, c in BUILTIN.items() if issubclass(c, LearnedAgent)]


def _obs(t: float, text: str, speed: float = 5.0, seed: int = 0) -> Observation:
    rng = np.random.default_rng(seed)
    bev = (rng.random((7, 128, 128)) < 0.1).astype(np.uint8) * 255
    bev[0, :, 48:80] = 255
    return Observation(t=t, bev=bev, speed=speed, instruction=text, instruction_id=0, notice="")


def test_two_learned_agents_ship_and_are_registered():
    assert len(SHIPPED) >= 2 and set(SHIPPED) <= set(LEARNED)
    for name in SHIPPED:
        assert (CHECKPOINTS / f"{name}.toml").is_file() and (CHECKPOINTS / f"{name}.md").is_file()
        assert (CHECKPOINTS / f"{name}.npz").stat().st_size < 4 * 2**20
        assert (CHECKPOINTS / f"{name}.pt").stat().st_size < 20 * 2**20


@pytest.mark.parametrize("name", SHIPPED)
def test_checkpoint_loads_weights_only(name):
    from icrsumo.learn.exact.checkpoint import load

    ck = torch.load(CHECKPOINTS / f"{name}.pt", weights_only=True)
    assert ck["format"] == "icrsumo-agent/1" and ck["meta"]["steps"] > 0
    exact = load(CHECKPOINTS / f"{name}.npz")
    assert exact.meta["source"] == f"{name}.pt" and exact.meta["source_meta"]["steps"] == ck["meta"]["steps"]


@pytest.mark.parametrize("name", SHIPPED)
def test_agent_acts_deterministically(name):
    def run():
        a = make_agent(name)
        a.reset(EpisodeInfo("r", "t", "n", 0.05, 0.1, 0))
        return [a.act(_obs(0.1 * i, "Turn left at the next junction.", speed=0.0 if i > 2 else 4.0, seed=i))
                for i in range(6)]
    for x, y in zip(run(), run()):
        np.testing.assert_array_equal(x.waypoints, y.waypoints)
        assert x.target_speed == y.target_speed
        assert x.waypoints.shape == (8, 2) and np.isfinite(x.waypoints).all()


@pytest.mark.parametrize("name", SHIPPED)
def test_batched_inference_matches_single(name):
    agents = [make_agent(name) for _ in range(3)]
    obs = [_obs(0.0, t, seed=i) for i, t in enumerate(["Turn left.", "Go straight.", "Follow the road."])]
    batched = act_batch(agents, obs)
    for a in agents:
        a.reset(EpisodeInfo("r", "t", "n", 0.05, 0.1, 0))
    single = [a.act(o) for a, o in zip(agents, obs)]
    for b, s in zip(batched, single):
        np.testing.assert_array_equal(b.waypoints, s.waypoints)   # bitwise on CPU


@pytest.mark.parametrize("name", SHIPPED[:1])
def test_learned_agent_closed_loop_is_repeatable(name, converted, generated):
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.results.logs import dumps_log
    from icrsumo.sim.episode import run_episode
    from icrsumo.world.scenario import find_scenarios, read_scenario

    sc = read_scenario(find_scenarios(converted["tiny"])[0])
    iset = read_instruction_sets(generated["tiny"] / f"{sc.route_id}.json")[0]
    a = dumps_log(run_episode(sc, iset, make_agent(name)))
    b = dumps_log(run_episode(sc, iset, make_agent(name)))
    assert a == b


def test_a_shipped_agent_loads_the_shipped_checkpoint_whatever_the_cwd(tmp_path, monkeypatch):
    """A file named like a shipped checkpoint in the working directory (a copy of an older
    checkpoint, say) must not replace the shipped one: it did, silently, before."""
    import shutil

    from icrsumo.learn.agent import checkpoint_path

    other = tmp_path / "bev-ngram.pt"
    shutil.copy(CHECKPOINTS / "bev-token.pt", other)
    monkeypatch.chdir(tmp_path)
    for name in SHIPPED:
        cls = BUILTIN[name]
        assert checkpoint_path(cls.checkpoint) == CHECKPOINTS / f"{name}.npz"
