"""The learned agents' instruction memory (icrsumo.learn.memory) on hand-made observations: a
turn or lane change used up once driven, a distance instruction held until its distance is near,
a new instruction starting afresh; and the agent feeding the network the memory's text."""

from __future__ import annotations

import math

import numpy as np
import pytest

from icrsumo.agents.base import EpisodeInfo, Observation
from icrsumo.learn.memory import (
    FOLLOW_TEXT,
    HOLD_MARGIN_M,
    SETTLED_M,
    InstructionMemory,
    stated_distance,
)

DT = 0.1
BEV = np.zeros((7, 128, 128), np.uint8)


def _obs(text: str, iid: int = 0, compass: float = 0.0, speed: float = 5.0,
         answer: bool = False) -> Observation:
    return Observation(t=0.0, bev=BEV, speed=speed, instruction=text, instruction_id=iid, notice="",
                       compass=compass, answer=answer)


def _drive(mem: InstructionMemory, text: str, headings, iid: int = 0, speed: float = 5.0) -> list[str]:
    return [mem.text(_obs(text, iid, h, speed), DT) for h in headings]


@pytest.mark.parametrize("text, sign, degrees, used", [
    ("Turn left at the next intersection.", +1, 90, True),
    ("Turn left at the next intersection.", -1, 90, False),   # a right bend leaves a left turn to come
    ("At the traffic light, make a right turn.", -1, 90, True),
    ("At the end of the road, turn right.", -1, 170, True),  # sharp: not cut short at 60 degrees
    ("Go straight at the junction.", +1, 90, False),          # a road bend never uses up straight
])
def test_a_turn_is_used_up_once_driven_that_way_and_over(text, sign, degrees, used):
    mem = InstructionMemory()
    # the heading turns 3 degrees per step (0.5 m), starting near the wrap at pi, then holds
    start, steps = math.pi - 0.2, degrees // 3
    headings = [start + sign * math.radians(3 * min(i, steps)) for i in range(steps + 40)]
    out = _drive(mem, text, headings)
    assert out[: steps + 1] == [text] * (steps + 1)          # never while the heading still turns
    assert (out[-1] == FOLLOW_TEXT) is used
    if used:   # 8 m (16 steps) after the heading settled, and for good
        first = out.index(FOLLOW_TEXT)
        assert steps + SETTLED_M / 0.5 - 1 <= first <= steps + SETTLED_M / 0.5
        assert set(out[first:]) == {FOLLOW_TEXT}


def test_a_lane_change_is_used_up_once_the_ego_moved_a_lane_that_way_and_straightened():
    mem = InstructionMemory()
    # 10 degrees to the left of the heading it arrived at for 40 steps (0.087 m sideways per
    # step at 5 m/s: 2.5 m after 29), then straight again
    heads = [0.0] + [math.radians(10)] * 40 + [0.0] * 30
    out = _drive(mem, "Change to the left lane.", heads)
    assert out.index(FOLLOW_TEXT) == 41 + SETTLED_M / 0.5
    assert FOLLOW_TEXT not in _drive(InstructionMemory(), "Change to the right lane.", heads)


def test_a_distance_instruction_is_held_until_its_distance_is_near():
    text = "In 80 meters, turn left at the junction."
    assert stated_distance(text) == 80.0
    mem = InstructionMemory()
    out = _drive(mem, text, [0.0] * 200, speed=5.0)      # 0.5 m per step
    shown = out.index(text)
    assert out[:shown] == [FOLLOW_TEXT] * shown
    assert abs((shown + 1) * 0.5 - (80.0 - HOLD_MARGIN_M)) <= 0.5
    # a stop holds the odometer; a lane change or a follow instruction is never held
    mem = InstructionMemory()
    assert set(_drive(mem, text, [0.0] * 50, speed=0.0)) == {FOLLOW_TEXT}
    for other in ("Move into the left lane in 80 meters.", "Follow the road for 200 m."):
        assert _drive(InstructionMemory(), other, [0.0] * 3) == [other] * 3


def test_a_new_instruction_or_answer_starts_afresh_and_roundabouts_pass_through():
    mem = InstructionMemory()
    turn = "Turn left at the next intersection."
    assert _drive(mem, turn, [0.0, 1.2] + [1.6] * 20)[-1] == FOLLOW_TEXT
    assert _drive(mem, turn, [1.6, 1.6], iid=1) == [turn, turn]         # another id
    assert mem.text(_obs(turn, 1, 1.6, answer=True), DT) == turn         # the navigator's answer
    ring = "At the roundabout, take the third exit."
    assert _drive(InstructionMemory(), ring, [0.0, -1.2, 0.5, 1.6, 2.5]) == [ring] * 5
    assert _drive(InstructionMemory(), "", [0.0, 1.6]) == ["", ""]


@pytest.mark.sumo
def test_the_agent_feeds_the_network_the_memorys_text():
    from icrsumo.agents.registry import make_agent

    turn = "Turn left at the next intersection."
    seen: dict[bool, list[str]] = {}
    for memory in (True, False):
        agent = make_agent("bev-ngram-aug")
        agent.memory = memory
        agent.reset(EpisodeInfo("r", "t", "n", 0.05, 0.1, 0))
        seen[memory] = [agent.read(_obs(turn, 0, h)) for h in (0.0, 0.6) + (1.2,) * 20]
    assert seen == {True: [turn] * 18 + [FOLLOW_TEXT] * 4, False: [turn] * 22}


def test_in_real_episodes_the_compass_is_the_logged_heading_and_a_turn_is_used_up(converted, tmp_path):
    import icrsumo
    from icrsumo.agents.registry import make_agent
    from icrsumo.core.angles import wrap_angle
    from icrsumo.instructions.intent import classify_intent
    from icrsumo.sim.callbacks import EpisodeCallback

    seen: list[Observation] = []

    class Seen(EpisodeCallback):
        def on_observation(self, episode, obs):
            seen.append(obs)

    suite = icrsumo.load_suite(converted["tiny"], tmp_path / "out", k=1)
    used_up = 0
    for scenario in (suite.scenario("tiny_005"), suite.scenario("tiny_009")):   # turns then no new text
        agent, read = make_agent("bev-ngram-aug"), []

        def recorded(obs, read=read, memory=agent.read):
            read.append((obs.instruction, memory(obs)))
            return read[-1][1]

        agent.read = recorded
        seen.clear()
        log = icrsumo.run_episode(scenario, suite.instruction_sets[scenario.route_id][0], agent,
                                  callbacks=[Seen()])
        yaw = dict(zip(log.t, log.yaw))
        assert seen and all(o.compass == wrap_angle(yaw[o.t]) for o in seen)
        assert len(read) == len(seen)   # the memory is read once per decision
        used_up += sum(1 for text, fed in read if fed == FOLLOW_TEXT and classify_intent(text).value
                       in ("left", "right"))
    assert used_up > 0
