"""Leaderboard 1.0 scoring: golden episode logs plus edge cases."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from icrsumo.logs import log_from_dict
from icrsumo.metrics import PENALTIES, outside_lanes_pct, penalised_infractions, score_episode
from icrsumo.termination import replay
from icrsumo.types import EpisodeLog, Event, TerminationClass

GOLDEN = sorted((Path(__file__).parent / "data" / "golden").glob("*.json"))
TOL = 1e-6


def test_golden_folder_is_populated():
    assert len(GOLDEN) >= 20


@pytest.mark.parametrize("path", GOLDEN, ids=[p.stem for p in GOLDEN])
def test_golden(path: Path):
    doc = json.loads(path.read_text(encoding="utf-8"))
    assert doc["description"]
    log = log_from_dict(doc["log"], str(path))
    exp = doc["expected"]
    res = score_episode(log)
    assert res.rc == pytest.approx(exp["rc"], abs=TOL)
    assert res.is_ == pytest.approx(exp["is"], abs=TOL)
    assert res.ds == pytest.approx(exp["ds"], abs=TOL)
    assert res.termination == exp["termination"]
    assert res.termination_class.value == exp["termination_class"]
    assert [[i.kind, i.factor] for i in res.infractions] == exp["infractions"]
    assert res.outside_lanes_pct == pytest.approx(exp["outside_lanes_pct"], abs=TOL)
    assert res.ds == pytest.approx(round(res.rc * res.is_, 4), abs=1e-3)
    assert res.duration == pytest.approx(log.t[-1] - log.t[0], abs=1e-9)
    got = replay(log)
    if exp["replay"] is None:
        assert got is None
    else:
        assert got is not None
        assert got[0] == exp["replay"][0]
        assert got[1] == pytest.approx(exp["replay"][1], abs=TOL)


def _log(n: int = 5, *, route_length: float = 100.0, dx: float = 10.0, termination: str = "route_timeout",
         events: tuple[Event, ...] = (), outside: tuple[int, ...] | None = None) -> EpisodeLog:
    t = tuple(float(i) for i in range(n))
    x = tuple(dx * i for i in range(n))
    return EpisodeLog(
        route_id="r", agent="a", family="baseline", k=0, seed=1, step_length=1.0, route_length=route_length,
        t=t, x=x, y=(0.0,) * n, yaw=(0.0,) * n, speed=(dx,) * n, progress=x, instruction=(0,) * n,
        outside=outside if outside is not None else (0,) * n, route_dist=(0.0,) * n, events=events,
        termination=termination, termination_t=t[-1] if n else 0.0,
    )


def test_penalty_table():
    assert PENALTIES == {"collision_pedestrian": 0.50, "collision_vehicle": 0.60, "collision_static": 0.65,
                         "red_light": 0.70, "stop_sign": 0.80}


def test_no_steps_scores_zero():
    res = score_episode(_log(0, termination="sim_error"))
    assert (res.rc, res.is_, res.ds, res.duration, res.outside_lanes_pct) == (0.0, 1.0, 0.0, 0.0, 0.0)
    assert res.termination_class is TerminationClass.TO
    # a log without steps cannot have completed anything
    assert score_episode(_log(0, termination="completed")).rc == 0.0


def test_single_step_duration_zero():
    res = score_episode(_log(1))
    assert res.duration == 0.0 and res.rc == 0.0


def test_zero_distance_driven_has_no_outside_penalty():
    log = _log(4, dx=0.0, outside=(1, 1, 1, 1))
    assert outside_lanes_pct(log) == 0.0
    assert score_episode(log).is_ == 1.0


def test_all_distance_outside_gives_is_zero():
    res = score_episode(_log(4, outside=(1, 1, 1, 1)))
    assert res.outside_lanes_pct == 100.0 and res.is_ == 0.0 and res.ds == 0.0


def test_partial_rc_and_clipping():
    assert score_episode(_log(5)).rc == 40.0  # 40 m of 100 m
    # progress beyond the route end (e.g. a looped route) clips to 100
    assert score_episode(_log(5, route_length=30.0)).rc == 100.0
    # negative progress (ego behind the route start) clips to 0
    neg = replace(_log(3), progress=(-5.0, -5.0, -5.0))
    assert score_episode(neg).rc == 0.0


def test_rc_thresholds():
    # 2000 m route: 99 % is 1980 m
    log = replace(_log(3, route_length=2000.0), progress=(0.0, 1000.0, 1979.9))
    assert score_episode(log).rc == pytest.approx(98.995)
    assert score_episode(replace(log, progress=(0.0, 1000.0, 1980.0))).rc == 100.0
    # 100 m route: 10 m radius applies at 90 m
    log = replace(_log(3), progress=(0.0, 50.0, 89.99))
    assert score_episode(log).rc == 89.99
    assert score_episode(replace(log, progress=(0.0, 50.0, 90.0))).rc == 100.0
    # completed flag wins even short of the end
    assert score_episode(replace(log, termination="completed")).rc == 100.0


def test_rounding():
    log = replace(_log(3, route_length=300.0), progress=(0.0, 10.0, 100.0))
    res = score_episode(log)
    assert res.rc == 33.3333
    ev = (Event("collision_static", 1.0, 10.0), Event("collision_static", 2.0 + 5.0, 10.0),
          Event("stop_sign", 2.0, 10.0))
    res = score_episode(replace(log, events=ev))
    assert res.is_ == round(0.65 * 0.65 * 0.8, 6)
    assert res.ds == round(100 / 3 * 0.65 * 0.65 * 0.8, 4)


def test_infractions_sorted_and_first_occurrence_kept():
    ev = (Event("red_light", 5.0, 50.0, "J2"), Event("collision_vehicle", 3.5, 35.0, "v1"),
          Event("collision_vehicle", 2.0, 20.0, "v1"))
    infs = penalised_infractions(ev)
    assert [(i.kind, i.t, i.pos, i.other) for i in infs] == [
        ("collision_vehicle", 2.0, 20.0, "v1"), ("red_light", 5.0, 50.0, "J2")]


def test_static_runs_chain_and_boundary():
    def n(times):
        return len(penalised_infractions(tuple(Event("collision_static", t, 0.0) for t in times)))

    assert n([0.0, 4.9]) == 1
    assert n([0.0, 5.0]) == 2  # exactly 5 s apart is a new collision
    assert n([0.0, 4.0, 8.0, 12.0]) == 1  # a run: each event < 5 s after the previous
    assert n([0.0, 4.0, 9.5]) == 2


def test_actor_collisions_keyed_by_kind_and_actor():
    ev = (Event("collision_vehicle", 1.0, 0.0, "x"), Event("collision_pedestrian", 2.0, 0.0, "x"),
          Event("collision_pedestrian", 30.0, 0.0, "x"), Event("collision_pedestrian", 31.0, 0.0, "p2"))
    assert [i.kind for i in penalised_infractions(ev)] == [
        "collision_vehicle", "collision_pedestrian", "collision_pedestrian"]


def test_actor_collision_without_id_uses_time_runs():
    ev = (Event("collision_vehicle", 1.0, 0.0), Event("collision_vehicle", 1.1, 0.0),
          Event("collision_vehicle", 20.0, 0.0))
    assert len(penalised_infractions(ev)) == 2


def test_unknown_event_kind_and_termination_raise():
    with pytest.raises(ValueError, match="collison_vehicle"):
        score_episode(_log(3, events=(Event("collison_vehicle", 1.0, 0.0, "v"),)))
    with pytest.raises(ValueError, match="crashed"):
        score_episode(_log(3, termination="crashed"))


def test_result_is_deterministic_and_independent_of_event_order():
    ev = (Event("red_light", 1.0, 10.0, "J"), Event("collision_vehicle", 2.0, 20.0, "v"),
          Event("collision_vehicle", 2.1, 20.0, "v"))
    a = score_episode(_log(5, events=ev))
    b = score_episode(_log(5, events=tuple(reversed(ev))))
    assert a == b
