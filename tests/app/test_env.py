"""The Gymnasium environment icrsumo/ICRDrive-v0: check_env, determinism, the same closed loop as
run_episode, reward and metrics, and the README's example (run exactly as printed)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

from gymnasium.utils.env_checker import check_env  # noqa: E402

import icrsumo.app.env  # noqa: E402,F401 - registers the id
from icrsumo.agents.base import Action, AgentError  # noqa: E402
from icrsumo.results.logs import dumps_log  # noqa: E402
from icrsumo.scoring import score_episode  # noqa: E402
from icrsumo.scoring.criteria import run_monitor  # noqa: E402
from icrsumo.scoring.lb1 import LB1_RULES  # noqa: E402
from icrsumo.scoring.route import dense_route  # noqa: E402
from icrsumo.sim.episode import run_episode  # noqa: E402
from icrsumo.world.dynamics import Control  # noqa: E402

pytestmark = pytest.mark.sumo

README = Path(__file__).resolve().parents[2] / "docs" / "gym.md"  # the page that holds the example


def _policy(obs) -> np.ndarray:
    """Hold about 6 m/s, straight ahead (representable exactly in float32)."""
    return np.array([0.0, 0.5 if obs["speed"][0] < 6.0 else 0.0, 0.0], dtype=np.float32)


class _Same:
    """The same policy as an agent of the protocol, for the comparison with run_episode."""

    name = "gymnasium"
    privileged = False

    def reset(self, info):
        pass

    def act(self, obs):
        return Action(control=Control(steer=0.0, throttle=0.5 if np.float32(obs.speed) < 6.0 else 0.0,
                                      brake=0.0))


@pytest.mark.parametrize("kwargs", [{"render_mode": "rgb_array"},
                                    {"action_type": "waypoints", "text_space": "bytes"}])
def test_check_env_passes(cache, kwargs):
    env = gym.make("icrsumo/ICRDrive-v0", **kwargs)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    env.close()
    msgs = [str(w.message) for w in caught]
    if kwargs.get("action_type") == "waypoints":  # a waypoint box in metres is not normalised, by design
        msgs = [m for m in msgs if "symmetric and normalized" not in m]
    assert msgs == []


def test_rollout_matches_run_episode_and_reports_metrics(cache):
    env = gym.make("icrsumo/ICRDrive-v0")
    obs, info = env.reset(seed=3)
    assert obs["bev"].shape == (7, 128, 128) and obs["bev"].dtype == np.uint8
    assert info["route_id"] == "tiny_003" and info["family"] == "baseline"
    assert obs["instruction"] and obs["instruction"] in env.observation_space["instruction"]
    total, steps = 0.0, 0
    while True:
        obs, reward, terminated, truncated, info = env.step(_policy(obs))
        total += reward
        steps += 1
        if terminated or truncated:
            break
    log = env.unwrapped.episode_log()
    env.close()
    # the same closed loop as icrsumo evaluate: same actions, byte-identical log
    sc, sets = env.unwrapped.scenario, list(env.unwrapped.sets.values())
    ref = run_episode(sc, sets[0], _Same())
    assert dumps_log(log) == dumps_log(ref)
    r = score_episode(ref)
    assert (info["DS"], info["RC"], info["IS"], info["termination"]) == (r.ds, r.rc, r.is_, r.termination)
    assert terminated == (r.termination_class.value != "TO") and truncated == (not terminated)
    assert [i["kind"] for i in info["infractions"]] == [i.kind for i in r.infractions]
    # the documented reward: RC, minus 100 (1 - f) per event infraction, minus 100 x (route
    # advance made off the lanes) / route length
    penalty = sum(100 * (1 - i.factor) for i in r.infractions if i.kind != "outside_route_lanes")
    mon, _ = run_monitor(ref, LB1_RULES)
    expected = mon.completion_pct - penalty - 100 * mon.outside_m / dense_route(ref).length
    assert total == pytest.approx(expected, abs=1e-9)
    assert steps == len(range(0, len(ref.t) - 1, 2))  # one step per decision (every 2nd SUMO step)


def test_reset_is_deterministic_and_options_pick_the_sequence(cache):
    env = gym.make("icrsumo/ICRDrive-v0")
    a, _ = env.reset(seed=1)
    for _ in range(15):
        a, *_ = env.step(np.array([0.1, 0.6, 0.0], np.float32))
    b, _ = env.reset(seed=2)
    for _ in range(15):
        b, *_ = env.step(np.array([0.1, 0.6, 0.0], np.float32))
    assert np.array_equal(a["bev"], b["bev"]) and a["speed"] == b["speed"]
    _, info = env.reset(options={"family": "misleading", "k": 3})
    assert (info["family"], info["k"]) == ("misleading", 3)
    with pytest.raises(AgentError, match="NaN"):
        env.step(np.array([np.nan, 0.0, 0.0], np.float32))
    from icrsumo.core.errors import InputError

    with pytest.raises(InputError, match="'famly': unknown reset option .*did you mean 'family'"):
        env.reset(options={"famly": "misleading"})      # never a silent baseline
    with pytest.raises(InputError, match="options: list: must be a dict"):
        env.reset(options=["misleading"])
    with pytest.raises(InputError, match="k: must be an integer, not '3'"):
        env.reset(options={"family": "misleading", "k": "3"})
    env.close()


def test_second_env_in_a_process_suspends_the_first(cache):
    first = gym.make("icrsumo/ICRDrive-v0")
    first.reset()
    second = gym.make("icrsumo/ICRDrive-v0")
    second.reset()
    second.step(np.zeros(3, np.float32))
    with pytest.raises(RuntimeError, match="AsyncVectorEnv"):
        first.step(np.zeros(3, np.float32))
    first.reset()  # takes the simulation back
    first.step(np.zeros(3, np.float32))
    first.close()
    second.close()


def test_readme_gymnasium_example_runs(cache, tmp_path):
    """The README's Gymnasium example, exactly as printed, in a fresh interpreter."""
    text = README.read_text(encoding="utf-8")
    blocks = [b for b in re.findall(r"```python\n(.*?)```", text, re.S) if "icrsumo/ICRDrive-v0" in b]
    assert len(blocks) == 1, "the README must hold exactly one Gymnasium example"
    env = {**os.environ, "ICRSUMO_CACHE": str(cache)}
    proc = subprocess.run([sys.executable, "-c", blocks[0]], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert re.search(r"return -?\d+\.\d  DS \d+\.\d  RC \d+\.\d", proc.stdout), proc.stdout


class _Reader:
    """An agent of the protocol that uses what the environment's helper must carry: the time,
    the instruction, its id and the episode info (exact float32 values: the env's box is float32)."""

    name = "gymnasium"  # the env's logs carry this agent name
    privileged = False

    def reset(self, info):
        self.dt = info.control_dt

    def act(self, obs):
        slow = "left" in obs.instruction.lower() and obs.instruction_id >= 0 and obs.t > 5.0
        target = 4.0 if slow else 6.0
        return Action(control=Control(steer=0.0, throttle=0.5 if np.float32(obs.speed) < target else 0.0,
                                      brake=0.25 if np.float32(obs.speed) > target + 1.0 else 0.0))


def test_an_icrsumo_agent_drives_the_env_through_the_helpers_as_in_evaluate(cache):
    from icrsumo.agents.base import EpisodeInfo
    from icrsumo.app.env import to_observation

    env = gym.make("icrsumo/ICRDrive-v0")
    obs, info = env.reset()
    assert isinstance(info["episode_info"], EpisodeInfo) and Path(info["net"]).is_file()
    agent = _Reader()
    agent.reset(info["episode_info"])
    while True:
        o = to_observation(obs, info)
        inner = env.unwrapped._obs  # what the closed loop observed this step
        assert (o.t, o.instruction, o.instruction_id, o.notice, o.compass) == (
            inner.t, inner.instruction, inner.instruction_id, inner.notice, inner.compass)
        obs, _, terminated, truncated, info = env.step(env.unwrapped.agent_action(agent.act(o)))
        if terminated or truncated:
            break
    log = env.unwrapped.episode_log()
    env.close()
    ref = run_episode(env.unwrapped.scenario, list(env.unwrapped.sets.values())[0], _Reader())
    assert dumps_log(log) == dumps_log(ref)  # the env and the helpers are evaluate's closed loop
    with pytest.raises(AgentError, match="takes control actions"):
        env.unwrapped.agent_action(Action(waypoints=np.zeros((3, 2))))


def test_with_asking_the_action_carries_an_ask_and_the_answer_is_observed(cache):
    """``asking=True``: a Dict action (the drive box and ``ask``); an ask is answered 2 simulated
    seconds later with the baseline's instruction for the maneuver ahead, observed as the
    instruction with ``info["answer"]``; the asks are counted in ``info`` and the episode log."""
    from icrsumo.app.env import ICRDriveEnv, to_observation
    from icrsumo.core.errors import InputError
    from icrsumo.sim.asking import ASK_DELAY

    env = gym.make("icrsumo/ICRDrive-v0", family="ambiguity", k=0, asking=True)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    assert [str(w.message) for w in caught] == []
    assert set(env.action_space.spaces) == {"control", "ask"}
    obs, info = env.reset()
    assert (info["answer"], info["asks"]) == (False, 0)
    turn = next(i for i in env.unwrapped.sets[("baseline", 0)].instructions if i.maneuver_pos is not None)
    asked_at = info["t"]
    obs, _, _, _, info = env.step({"control": _policy(obs), "ask": 1})
    assert info["asks"] == 1 and not info["answer"] and obs["instruction"] != turn.rendered()
    while not info["answer"]:
        obs, _, terminated, truncated, info = env.step({"control": _policy(obs), "ask": 0})
        assert not (terminated or truncated)
    assert info["t"] >= asked_at + ASK_DELAY - 1e-9 and info["t"] < asked_at + ASK_DELAY + 0.2
    assert (obs["instruction"], info["instruction_id"]) == (turn.rendered(), turn.id)
    assert to_observation(obs, info).answer is True and info["asks"] == 1
    log = env.unwrapped.episode_log()
    assert [(a.t, a.answered, a.instruction_id) for a in log.asks] == [(asked_at, True, turn.id)]
    drive = Action(control=Control(0.0, 0.5, 0.0), ask=True)
    wanted = env.unwrapped.agent_action(drive)
    assert wanted["ask"] == 1 and np.array_equal(wanted["control"], np.array([0.0, 0.5, 0.0], np.float32))
    with pytest.raises(AgentError, match="with asking the action is a dict with keys 'control' and 'ask'"):
        env.step(_policy(obs))
    with pytest.raises(AgentError, match=r"action\['ask'\] must be 0 or 1"):
        env.step({"control": _policy(obs), "ask": 2})
    env.close()
    sc, amb = env.unwrapped.scenario, env.unwrapped.sets[("ambiguity", 0)]
    with pytest.raises(InputError, match="asking: tiny_003: needs the route's baseline instruction sequence"):
        ICRDriveEnv(sc, amb, family="ambiguity", asking=True)
