"""The scoring registry (icrsumo.scoring.registry): names once, unknown names refused, a
third rule set is one module registered by name, no SUMO."""

from __future__ import annotations

import warnings

import pytest
from hand_logs import ROUTE, contact, make_log, straight  # tests/ is on pytest's pythonpath
from records_example import rec

from icrsumo.scoring import SCORINGS, get_scoring, register_scoring, score_episode, scoring_names
from icrsumo.scoring.lb1 import LB1, LB1_RULES, Leaderboard1


class _NoCollisions(Leaderboard1):
    """Leaderboard 1.0 that counts no collision and allows 10 s per route."""

    name = "test-no-collisions"
    title = "a test rule set"

    def counted_collisions(self, log):
        return []

    def time_budget(self, route_length):
        return 10.0

    def leaderboard_file(self, records, agent, family):
        return {"n": len(list(records))}


def test_scoring_registry_refuses_duplicates_and_unknown_names():
    assert "lb1" in SCORINGS and get_scoring("lb1") is LB1
    assert scoring_names()[:2] == ["lb1", "lb2"]
    with pytest.raises(ValueError, match="registered already"):
        register_scoring(Leaderboard1())
    with pytest.raises(ValueError, match="unknown scoring 'lb9' .known: lb1, lb2"):
        score_episode(make_log(straight(3), ROUTE), "lb9")


def test_a_third_rule_set_is_one_class_registered_by_name():
    log = make_log(straight(201), ROUTE, events=(contact("collision_vehicle", 20, "veh1"),),
                   termination="completed")
    register_scoring(_NoCollisions())
    try:
        assert scoring_names()[-1] == "test-no-collisions"
        assert score_episode(log, "test-no-collisions").is_ == 1.0
        assert score_episode(log).is_ == pytest.approx(0.6)  # lb1, the default, counts it
        third = get_scoring("test-no-collisions")
        assert third.rules is LB1_RULES and third.max_steps(500.0, 0.05) == int(20.0 / 0.05) + 10
        assert third.leaderboard_file([rec("B", "r1", "noise", 0, 100, 100, 1.0)], "B", "noise") == {"n": 1}
    finally:
        del SCORINGS["test-no-collisions"]


def test_the_old_module_names_are_the_new_ones():
    with warnings.catch_warnings():  # the warning itself: tests/test_imports.py
        warnings.simplefilter("ignore", DeprecationWarning)
        from icrsumo import metrics, termination
    from icrsumo.scoring.criteria import replay
    from icrsumo.scoring.route import DenseRoute

    assert metrics.score_episode is score_episode and metrics.SCORINGS is SCORINGS
    assert metrics.penalised_infractions(make_log(straight(3), ROUTE)) == ()
    assert termination.replay is replay and termination.DenseRoute is DenseRoute
    assert termination.ROUTE_RULES["lb1"] is LB1_RULES
