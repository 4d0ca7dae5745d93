"""Run-ending rules: the incremental monitor and replay over logs."""

from __future__ import annotations

import pytest

from icrsumo.termination import (
    BLOCKED_S,
    DEVIATION_M,
    TerminationMonitor,
    is_route_complete,
    replay,
    route_timeout,
)
from icrsumo.types import EpisodeLog, Event


def mon(route_length: float = 1000.0, start_t: float = 0.0) -> TerminationMonitor:
    return TerminationMonitor(route_length, start_t)


def test_constants():
    assert DEVIATION_M == 30.0 and BLOCKED_S == 180.0
    assert route_timeout(100.0) == 85.0
    assert route_timeout(0.0) == 5.0


def test_moving_on_route_is_fine():
    m = mon()
    assert m.update(0.0, 0.0, 0.0, 5.0) is None
    assert m.update(1.0, 5.0, 1.0, 5.0) is None
    assert m.result is None


def test_deviation_boundary():
    assert mon().update(1.0, 10.0, 30.0, 5.0) is None
    assert mon().update(1.0, 10.0, 30.01, 5.0) == "route_deviation"


def test_completion_boundaries():
    assert is_route_complete(1980.0, 2000.0)
    assert not is_route_complete(1979.99, 2000.0)
    assert is_route_complete(90.0, 100.0)
    assert not is_route_complete(89.99, 100.0)
    assert is_route_complete(0.0, 8.0)  # a route shorter than 10 m is complete at once
    assert mon(100.0).update(1.0, 90.0, 0.0, 5.0) == "completed"
    assert mon(100.0).update(1.0, 89.99, 0.0, 5.0) is None


def test_blocked_after_180s_from_first_slow_step():
    m = mon(start_t=0.0, route_length=10000.0)
    assert m.update(0.0, 0.0, 0.0, 5.0) is None
    for i in range(1, 2000):  # slow from t=0.1; 0.1 steps accumulate float error on purpose
        t = i * 0.1
        kind = m.update(t, 0.0, 0.0, 0.0)
        if kind:
            break
    assert kind == "agent_blocked"
    assert t == pytest.approx(180.1)


def test_blocked_boundary_and_reset():
    m = mon(route_length=10000.0)
    assert m.update(10.0, 0.0, 0.0, 0.05) is None  # slow from t=10
    assert m.update(189.99, 0.0, 0.0, 0.0) is None
    assert m.blocked_for(189.99) == pytest.approx(179.99)
    assert m.update(190.0, 0.0, 0.0, 0.0) == "agent_blocked"

    m = mon(route_length=10000.0)
    assert m.update(10.0, 0.0, 0.0, 0.0) is None
    assert m.update(100.0, 0.0, 0.0, 0.1) is None  # exactly 0.1 m/s is moving: timer resets
    assert m.blocked_for(100.0) == 0.0
    assert m.update(110.0, 0.0, 0.0, 0.0999) is None  # slow again from t=110
    assert m.update(190.0, 0.0, 0.0, 0.0) is None
    assert m.update(289.0, 0.0, 0.0, 0.0) is None
    assert m.update(290.0, 0.0, 0.0, 0.0) == "agent_blocked"


def test_timeout_boundary():
    m = mon(route_length=100.0, start_t=2.0)  # 85 s budget, from t=2
    assert m.update(87.0, 0.0, 0.0, 5.0) is None
    assert m.update(87.001, 0.0, 0.0, 5.0) == "route_timeout"


def test_order_of_checks():
    ev_err = [Event("sim_error", 5.0, 0.0)]
    ev_tp = [Event("ego_teleport", 5.0, 0.0)]
    # sim_error beats everything, stuck beats completed, completed beats deviation
    assert mon(100.0).update(5.0, 95.0, 50.0, 0.0, ev_err + ev_tp) == "sim_error"
    assert mon(100.0).update(5.0, 95.0, 50.0, 0.0, ev_tp) == "stuck"
    assert mon(100.0).update(5.0, 95.0, 50.0, 0.0) == "completed"
    # deviation beats blocked and timeout
    m = mon(20.0)  # timeout 21 s
    m.update(0.0, 0.0, 0.0, 0.0)
    assert m.update(200.0, 0.0, 31.0, 0.0) == "route_deviation"
    # blocked beats timeout
    m = mon(20.0)
    m.update(0.0, 0.0, 0.0, 0.0)
    assert m.update(200.0, 0.0, 0.0, 0.0) == "agent_blocked"
    # other events do not end a run
    assert mon().update(1.0, 0.0, 0.0, 5.0, [Event("collision_vehicle", 1.0, 0.0, "v")]) is None


def test_monitor_is_sticky_and_checks_time():
    m = mon()
    assert m.update(1.0, 0.0, 40.0, 5.0) == "route_deviation"
    assert m.update(2.0, 0.0, 0.0, 5.0) == "route_deviation"
    assert m.result == ("route_deviation", 1.0)
    m = mon()
    m.update(2.0, 0.0, 0.0, 5.0)
    with pytest.raises(ValueError, match="backwards"):
        m.update(1.0, 0.0, 0.0, 5.0)
    with pytest.raises(ValueError):
        TerminationMonitor(float("nan"), 0.0)


def _log(events=(), n=10, step=1.0) -> EpisodeLog:
    t = tuple(i * step for i in range(n))
    return EpisodeLog(
        route_id="r", agent="a", family="baseline", k=0, seed=0, step_length=step, route_length=1000.0,
        t=t, x=(0.0,) * n, y=(0.0,) * n, yaw=(0.0,) * n, speed=(5.0,) * n, progress=(0.0,) * n,
        instruction=(0,) * n, outside=(0,) * n, route_dist=(0.0,) * n, events=tuple(events),
        termination="sim_error", termination_t=t[-1] if n else 0.0,
    )


def test_replay_attaches_events_within_half_a_step():
    assert replay(_log()) is None
    assert replay(_log(n=0)) is None
    assert replay(_log([Event("ego_teleport", 3.4, 0.0)])) == ("stuck", 3.0)
    assert replay(_log([Event("ego_teleport", 3.6, 0.0)])) == ("stuck", 4.0)
    assert replay(_log([Event("sim_error", 3.5, 0.0)])) == ("sim_error", 3.0)  # tie: earlier step
    # events after the last step (the runner logs no step for a failed or teleported step)
    assert replay(_log([Event("sim_error", 9.6, 0.0)])) == ("sim_error", 9.6)
    both = [Event("ego_teleport", 10.0, 0.0), Event("sim_error", 10.0, 0.0)]
    assert replay(_log(both)) == ("sim_error", 10.0)
    assert replay(_log([Event("collision_vehicle", 10.0, 0.0, "v")])) is None
    assert replay(_log([Event("ego_teleport", 0.0, 0.0)], n=0)) == ("stuck", 0.0)
    # but a rule that fired on the steps comes first
    assert replay(_log([Event("ego_teleport", 2.0, 0.0), Event("sim_error", 12.0, 0.0)])) == ("stuck", 2.0)
    assert replay(_log([Event("sim_error", -0.5, 0.0)])) == ("sim_error", 0.0)
    # first rule wins over later events
    assert replay(_log([Event("sim_error", 6.0, 0.0), Event("ego_teleport", 2.0, 0.0)])) == ("stuck", 2.0)
