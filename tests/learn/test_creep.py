"""The learned agents' creep out of a standstill (icrsumo.learn.creep): on rasters drawn here, and
in real closed-loop episodes at one of the tiny suite's all-way stops."""

from __future__ import annotations

import numpy as np
import pytest

from icrsumo.agents.base import Action, EpisodeInfo, Observation
from icrsumo.learn import creep as C
from icrsumo.learn.creep import AFTER_S, CREEP_S, CREEP_SPEED, Creep

DT = 0.1
WPS = np.array([[2.5, 0.0], [5.0, 0.1]])


def _bev() -> np.ndarray:
    """The default raster (7, 128, 128) with the ego of a 5 x 2.5 m car at its place."""
    bev = np.zeros((7, 128, 128), dtype=np.uint8)
    bev[C.EGO, 91:101, 62:67] = 255
    return bev


def _at(bev: np.ndarray, channel: int, ahead_m: float, left_m: float = 0.0) -> np.ndarray:
    """``bev`` with a 2 x 2 px blob in ``channel``, ``ahead_m`` ahead of the ego's centre and
    ``left_m`` to its left."""
    out = bev.copy()
    r, c = int(96 - ahead_m / 0.5), int(64 - left_m / 0.5)
    out[channel, r:r + 2, c:c + 2] = 255
    return out


def _obs(t: float, bev: np.ndarray, speed: float = 0.0, notice: str = "",
         text: str = "Turn left.") -> Observation:
    return Observation(t=t, bev=bev, speed=speed, instruction=text, instruction_id=0, notice=notice)


def _stand(watch: Creep, bevs, t0: float = 0.0, seconds: float = AFTER_S + CREEP_S + 1.0,
           **kw) -> list[Action]:
    """The actions while the ego stands from ``t0`` on and the network asks to stop; ``bevs``
    is one raster or a function of the time."""
    out, t = [], t0
    stop = Action(waypoints=WPS, target_speed=0.0)
    while t < t0 + seconds - 1e-9:
        bev = bevs(t) if callable(bevs) else bevs
        out.append(watch.action(_obs(round(t, 3), bev, **kw), stop))
        t += DT
    return out


def _creeping(actions: list[Action]) -> list[bool]:
    return [a.target_speed >= CREEP_SPEED for a in actions]


def test_the_channel_indices_are_the_renderers():
    from icrsumo.render import CHANNELS

    renderer = tuple(CHANNELS.index(n) for n in ("vehicles", "pedestrians", "ego", "stop", "go"))
    assert renderer == (C.VEHICLES, C.PEDESTRIANS, C.EGO, C.STOP, C.GO)


def test_an_ego_standing_with_nothing_in_view_creeps_after_the_wait_along_the_networks_path():
    watch = Creep()
    acts = _stand(watch, _bev())
    creeping = _creeping(acts)
    first = creeping.index(True)
    assert abs(first * DT - AFTER_S) < DT + 1e-9                 # not before the wait is over
    assert sum(creeping) == round(CREEP_S / DT)                    # for CREEP_S, then the network again
    assert all(a.waypoints is WPS for a in acts)                   # its path, only the speed overridden
    assert watch.creeps == 1


def test_moving_or_a_network_that_drives_resets_nothing_to_override():
    watch = Creep()
    stop = Action(waypoints=WPS, target_speed=0.0)
    # standing 9 s, moving once, standing 9 s again: the wait starts afresh
    for k in range(90):
        watch.action(_obs(k * DT, _bev()), stop)
    watch.action(_obs(9.0, _bev(), speed=1.0), stop)
    assert not any(_creeping(_stand(watch, _bev(), t0=9.1, seconds=9.5)))
    go = Action(waypoints=WPS, target_speed=3.0)
    assert watch.action(_obs(30.0, _bev()), go) is go


@pytest.mark.parametrize("channel,ahead,left,creeps", [
    (C.VEHICLES, 30.0, 10.0, False),      # a car far ahead and to the side: wait
    (C.PEDESTRIANS, 40.0, -12.0, False),  # a pedestrian anywhere ahead in view: wait
    (C.VEHICLES, -8.0, 0.0, True),        # a car behind holds nothing
    (C.VEHICLES, 20.0, 20.0, True),       # beyond 16 m to the side
])
def test_a_road_user_ahead_in_view_holds_the_creep(channel, ahead, left, creeps):
    assert any(_creeping(_stand(Creep(), _at(_bev(), channel, ahead, left)))) is creeps


def test_a_creep_under_way_ends_when_a_road_user_comes_into_view():
    clear, busy = _bev(), _at(_bev(), C.VEHICLES, 25.0, 3.0)
    acts = _stand(Creep(), lambda t: clear if t < AFTER_S + 1.0 else busy)
    creeping = _creeping(acts)
    assert any(creeping) and sum(creeping) < round(CREEP_S / DT)
    assert not any(creeping[int((AFTER_S + 1.0) / DT) + 1:])


def test_a_stop_line_ahead_is_a_red_light_unless_the_text_names_a_stop_sign_that_never_turned_green():
    line = _bev()
    line[C.STOP, 86:88, 58:71] = 255                              # the ego's stop line, 2.5 m ahead
    assert C.red_line_ahead(line) and not C.red_line_ahead(_bev())
    assert not any(_creeping(_stand(Creep(), line)))              # a red light: wait for green
    for notice, text in (("Stop sign ahead.", "Turn left."), ("", "Stop at the sign, then turn left.")):
        assert any(_creeping(_stand(Creep(), line, notice=notice, text=text)))
    green_once = _at(line, C.GO, 20.0, 10.0)                       # a light: it was green somewhere
    bevs = lambda t: green_once if 2.0 <= t < 2.2 else line     # noqa: E731
    assert not any(_creeping(_stand(Creep(), bevs, notice="Stop sign ahead.")))
    far = _bev()
    far[C.STOP, 30:32, 58:71] = 255                                # 30 m ahead: not this lane's line yet
    assert any(_creeping(_stand(Creep(), far)))


def test_the_agent_creeps_only_with_creep_on():
    from icrsumo.agents.registry import make_agent

    stop = Action(waypoints=WPS, target_speed=0.0)
    for on in (True, False):
        agent = make_agent("bev-ngram-aug")
        agent.creep = on
        agent.reset(EpisodeInfo("r", "t", "n", 0.05, DT, 0))
        acts = [agent.decide(_obs(k * DT, _bev()), stop) for k in range(round((AFTER_S + 1.0) / DT))]
        assert any(_creeping(acts)) is on


@pytest.mark.sumo
def test_at_an_all_way_stop_the_agent_drives_on_only_with_the_creep(converted, tmp_path):
    """tiny_013: the default agent stops at the all-way stop sign; without the creep its network
    never starts again and the episode runs to the route's time-out."""
    import icrsumo
    from icrsumo.agents.registry import make_agent
    from icrsumo.scoring import score_episode

    suite = icrsumo.load_suite(converted["tiny"], tmp_path / "out", k=1)
    sc = suite.scenario("tiny_013")
    ends = {}
    for on in (True, False):
        agent = make_agent("bev-ngram-aug")
        agent.creep = on
        log = icrsumo.run_episode(sc, suite.instruction_set("tiny_013"), agent)
        ends[on] = (score_episode(log).termination, agent.watch.creeps)
    assert ends[True][0] == "completed" and ends[True][1] >= 1
    assert ends[False] == ("route_timeout", 0)
