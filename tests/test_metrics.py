"""Leaderboard 1.0 scoring (icrsumo.metrics) on hand-built logs, no SUMO.

Logs are built as in tests/test_termination.py: 20 Hz steps, the ego centre at x = 0.25 + 0.5 i
on step i (t = 0.05 i), a straight 100 m route along +x unless stated. Expected values are
worked out in the comments from the leaderboard's rules (statistics_manager.py,
CollisionTest, OutsideRouteLanesTest).
"""

from __future__ import annotations

import pytest
from test_termination import make_log, straight

from icrsumo.metrics import PENALTIES, SCORINGS, Scoring, counted_collisions, register_scoring, score_episode
from icrsumo.types import Event

ROUTE = ((0.0, 0.0), (100.0, 0.0))


def contact(kind: str, i: int, other: str) -> Event:
    return Event(kind, round(0.05 * i, 3), 0.0, other, 0.25 + 0.5 * i, 0.0)


def test_penalty_constants():
    assert {str(k): v for k, v in PENALTIES.items()} == {
        "collision_pedestrian": 0.5, "collision_vehicle": 0.6, "collision_static": 0.65, "red_light": 0.7,
        "stop_sign": 0.8}


def test_clean_completion():
    res = score_episode(make_log(straight(201), ROUTE, termination="completed"))
    assert (res.rc, res.is_, res.ds, res.infractions, res.outside_lanes_pct) == (100.0, 1.0, 100.0, (), 0.0)


def test_repeated_contacts_with_one_actor():
    # veh1 touches on steps 20-29 (t 1.0-1.45): counted once at t = 1.0 (the same actor is then
    # ignored); at step 100 (t = 5.0) it is still the last actor (5.0 - 1.0 <= 5 s): ignored; it
    # is forgotten at t = 6.05 (> 5 s), so the contact at step 140 (t = 7.0, 60 m from the first
    # place, which was forgotten beyond 5 m) counts again: 2 x 0.6 -> IS 0.36
    evs = tuple(contact("collision_vehicle", i, "veh1") for i in [*range(20, 30), 100, 140, 141])
    log = make_log(straight(201), ROUTE, events=evs, termination="completed")
    assert [e.t for e in counted_collisions(log)] == [1.0, 7.0]
    res = score_episode(log)
    assert res.is_ == pytest.approx(0.36) and res.ds == pytest.approx(36.0)


def test_two_actors_at_one_place_and_static_contacts():
    # veh1 at step 20 (x = 10.25) counts there; veh2 at step 24 (x = 12.25, 2 m away) is within
    # 3 m of that place: ignored; veh3 at step 28 (x = 14.25, 4 m) counts; the roadside at
    # step 30 (x = 15.25, 1 m from the last place) is ignored; the roadside at step 60
    # (x = 30.25) counts, again at step 64 (2 m) is ignored, at step 70 (x = 35.25, 5 m) counts
    # (the static layout has no identity, only places): 0.6^2 x 0.65^2 = 0.1521
    evs = (contact("collision_vehicle", 20, "veh1"), contact("collision_vehicle", 24, "veh2"),
           contact("collision_vehicle", 28, "veh3"), contact("collision_static", 30, "roadside"),
           contact("collision_static", 60, "roadside"), contact("collision_static", 64, "roadside"),
           contact("collision_static", 70, "roadside"))
    log = make_log(straight(201), ROUTE, events=evs, termination="completed")
    assert [(e.other, e.t) for e in counted_collisions(log)] == [
        ("veh1", 1.0), ("veh3", 1.4), ("roadside", 3.0), ("roadside", 3.5)]
    assert score_episode(log).is_ == pytest.approx(0.1521)


def test_pedestrian_red_light_and_stop_sign_factors():
    evs = (contact("collision_pedestrian", 10, "p0"), Event("red_light", 2.0, 0.0, "tl1"),
           Event("stop_sign", 3.0, 0.0, "j2"), Event("wrong_way", 3.5, 0.0, "e_0"))
    res = score_episode(make_log(straight(201), ROUTE, events=evs, termination="completed"))
    assert [str(i.kind) for i in res.infractions] == ["collision_pedestrian", "red_light", "stop_sign"]
    assert res.is_ == pytest.approx(0.5 * 0.7 * 0.8)


def test_a_wrong_turn_into_a_legal_lane_costs_rc_not_is():
    # as in test_termination: deviation at (50, 30) with RC 24.5 %; the lane taken is legal
    # (no outside bits), so IS stays 1: DS = 24.5
    xy = straight(100) + [(50.0, 0.5 * j) for j in range(1, 61)]
    res = score_episode(make_log(xy, ((0.0, 0.0), (200.0, 0.0)), termination="route_deviation"))
    assert (res.rc, res.is_, res.ds) == (24.5, 1.0, 24.5)
    assert res.infractions == ()


def test_driving_against_traffic_and_a_sidewalk_excursion():
    # wrong lane (bit 2) on the steps passing points 20..39, off every lane (bit 1) on those
    # passing points 60..69: 30 m of 100 m advanced -> IS 0.7, DS 70; one outside-lanes entry
    xy = straight(201)
    flags = [2 if 20 < x <= 40 else 1 if 60 < x <= 70 else 0 for x, _ in xy]
    res = score_episode(make_log(xy, ROUTE, outside=flags, termination="completed"))
    assert res.outside_lanes_pct == pytest.approx(30.0)
    assert (res.rc, res.is_, res.ds) == (100.0, 0.7, 70.0)
    assert [(str(i.kind), round(i.factor, 6)) for i in res.infractions] == [("outside_route_lanes", 0.7)]


def test_no_outside_entry_without_advance_off_the_lanes():
    # four static collisions 10 m apart give IS 0.65^4 = 0.178506 and no outside-lanes entry
    evs = tuple(contact("collision_static", i, "roadside") for i in (20, 40, 60, 80))
    res = score_episode(make_log(straight(201), ROUTE, events=evs, termination="completed"))
    assert res.is_ == 0.178506
    assert [str(i.kind) for i in res.infractions] == ["collision_static"] * 4


def test_empty_log_scores_zero():
    log = make_log([], ROUTE, termination="sim_error")
    res = score_episode(log)
    assert (res.rc, res.is_, res.ds, res.duration) == (0.0, 1.0, 0.0, 0.0)


def test_scoring_registry_refuses_duplicates_and_unknown_names():
    assert "lb1" in SCORINGS
    with pytest.raises(ValueError, match="registered already"):
        register_scoring(Scoring("lb1", "again", SCORINGS["lb1"].score))
    with pytest.raises(ValueError, match="unknown scoring"):
        score_episode(make_log(straight(3), ROUTE), "lb9")
