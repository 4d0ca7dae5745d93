"""CARLA Leaderboard 1.0's scoring (``lb1``, the default), whole: route criteria, collision
counting, step budget, per-route scores and the results file.

Reproduces ``leaderboard/utils/statistics_manager.py`` (``compute_route_statistics``,
``compute_global_statistics`` and ``save_global_record``, branch ``leaderboard-1.0``) over the
criteria of scenario_runner's ``srunner/scenariomanager/scenarioatomics/atomic_criteria.py``
(branch ``leaderboard-1.0``) as ``leaderboard/scenarios/route_scenario.py`` builds them for a
route (:mod:`icrsumo.scoring.criteria` runs them, replayed from the log for a stored episode):

* RC (0-100): ``RouteCompletionTest``'s percentage, 100 when the route was completed;
* IS (0-1): the product of one factor per counted infraction
  (:data:`~icrsumo.scoring.penalties.PENALTIES`: collision with a pedestrian 0.50, a vehicle
  0.60, the static layout 0.65, red light 0.70, stop sign 0.80), times ``1 - pct / 100`` for
  ``OutsideRouteLanesTest``'s percentage when the ego made route progress off the driving
  lanes or in a lane of the opposite direction;
* DS = RC x IS.

Collisions are counted as ``CollisionTest`` counts them (:class:`CollisionCounter`); the route
timeout is ``route_scenario.py``'s ``int(0.8 s/m x route length + 5 s)``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

from icrsumo.core.types import EpisodeLog, EpisodeRecord, Event
from icrsumo.core.vocab import EpisodeStatus, EventKind

from .base import KeyPoints, Scoring
from .criteria import EPS, OFF_LANES, WRONG_LANE, RouteRules, events_by_step, route_timeout
from .leaderboard import LABELS, Logs, agent_records, crash_scored, record_infractions, route_name
from .penalties import MAX_ID_TIME, contacts

#: Leaderboard 1.0's route criteria (scenario_runner, branch leaderboard-1.0)
LB1_RULES = RouteRules("lb1", OFF_LANES | WRONG_LANE, None, "route", 0)

#: CollisionTest: a contact within this distance (m) of a counted one's place is not counted ...
MIN_AREA_OF_COLLISION = 3.0
#: ... and places are forgotten once the ego is farther than this (m) from them
MAX_AREA_OF_COLLISION = 5.0


class CollisionCounter:
    """Leaderboard 1.0's ``CollisionTest``, step by step: :meth:`step` takes one step's time (s),
    ego centre (m) and events, and returns the collisions counted there.

    The log holds one event per step of contact. Per step, in order: each contact is ignored
    when it is with the same actor as the last counted collision (vehicles and pedestrians,
    by ``other``; the static layout has no identity) or when the ego is within 3 m of a place
    where a collision was counted; otherwise it is counted there. Then places farther than
    5 m from the ego are forgotten, and the last actor once more than 5 s passed since the last
    counted collision."""

    def __init__(self) -> None:
        self.places: list[tuple[float, float]] = []
        self.last_id: str | None = None
        self.last_t = 0.0

    def step(self, t: float, x: float, y: float, events: Sequence[Event]) -> list[Event]:
        out: list[Event] = []
        for e, actor in contacts(events, self.last_id):
            if any(math.sqrt((x - px) ** 2 + (y - py) ** 2) <= MIN_AREA_OF_COLLISION
                   for px, py in self.places):
                continue
            out.append(e)
            self.last_t = t
            self.places.append((x, y))
            if actor:
                self.last_id = actor
        self.places = [(px, py) for px, py in self.places
                       if math.sqrt((x - px) ** 2 + (y - py) ** 2) <= MAX_AREA_OF_COLLISION]
        if self.last_id is not None and t - self.last_t > MAX_ID_TIME + EPS:
            self.last_id = None
        return out


def counted_collisions(log: EpisodeLog) -> list[Event]:
    """The collision events of ``log`` that :class:`CollisionCounter` counts, step by step (the
    positions are the ego centre of each step)."""
    by_step, _ = events_by_step(log)
    counter = CollisionCounter()
    out: list[Event] = []
    for i, evs in enumerate(by_step):
        if evs:
            out += counter.step(log.t[i], log.x[i], log.y[i], evs)
        elif counter.places or counter.last_id is not None:
            counter.step(log.t[i], log.x[i], log.y[i], ())
    return out


# --------------------------------------------------------------------------- the results file
#: Leaderboard 1.0 infraction keys, in the order of ``RouteRecord.infractions``.
LB_INFRACTIONS = ("collisions_pedestrian", "collisions_vehicle", "collisions_layout", "red_light",
                  "stop_infraction", "outside_route_lanes", "route_dev", "route_timeout", "vehicle_blocked")


def _wording(r: EpisodeRecord, kind: str, factor: float) -> tuple[str, str] | None:
    """1.0's outside-lanes entry (its percentage); other kinds are penalised events."""
    if kind == EventKind.OUTSIDE_ROUTE_LANES:
        return "outside_route_lanes", (f"Agent went outside its route lanes for about "
                                       f"{100.0 * (1.0 - factor):.2f}% of the completed route")
    return None


def key_point_length(points: Sequence[Sequence[float]]) -> float:
    """``compute_route_length``: the sum of the straight distances (m) between consecutive key
    points of a route (the route file's waypoints)."""
    return sum(math.dist(a, b) for a, b in zip(points, points[1:]))


def lb_route_length(r: EpisodeRecord, key_points: KeyPoints | None) -> float:
    """The leaderboard's route length (m) of ``r``'s route: its key points' length
    (:func:`key_point_length`), or the record's ``length`` (the route along its lanes) where
    they are not known."""
    points = (key_points or {}).get(r.route_id, ())
    length = key_point_length(points) if len(points) >= 2 else 0.0
    return round(length, 6) if length > 0 else r.length


def _lb_record(r: EpisodeRecord, index: int, length: float) -> dict:
    """One route's record. A crashed episode scored from its partial log has that log's scores
    (:func:`~icrsumo.scoring.leaderboard.crash_scored`); one without a log (no termination)
    scores 0, 1 and 0, what the leaderboard writes for a route whose criteria recorded nothing."""
    status, infr = record_infractions(r, LB_INFRACTIONS, _wording)
    crashed = r.status == EpisodeStatus.CRASHED and not r.termination
    return {
        "route_id": route_name(r),
        "index": index,
        "status": status,
        "infractions": infr,
        "scores": {"score_route": 0.0 if crashed else r.rc, "score_penalty": 1.0 if crashed else r.is_,
                   "score_composed": 0.0 if crashed else r.ds},
        "meta": {"route_length": length, "duration_game": r.duration, "duration_system": -1},
    }


def _rates(recs: Sequence[dict]) -> dict[str, float]:
    """Each infraction's rate: the sum over routes of the route's count over its km of route
    completed (RC / 100 x route length); a route with RC 0 adds nothing."""
    infr = {k: 0.0 for k in LB_INFRACTIONS}
    for rec in recs:
        rc = rec["scores"]["score_route"]
        if rc == 0:
            continue
        km = rc / 100.0 * rec["meta"]["route_length"] / 1000.0
        for k in LB_INFRACTIONS:
            infr[k] += len(rec["infractions"][k]) / km
    return {k: round(v, 6) for k, v in infr.items()}


def _entry_status(statuses: Sequence[str]) -> tuple[str, bool]:
    """``entry_status`` and ``eligible``: 'Crashed' (not eligible) when a simulation crashed, else
    'Finished with agent errors' when a status names the agent, else 'Finished'."""
    if "Failed - Simulation crashed" in statuses:
        return "Crashed", False
    if any("Agent" in st for st in statuses):
        return "Finished with agent errors", True
    return "Finished", True


def leaderboard_checkpoint(records: Iterable[EpisodeRecord], agent: str, family: str,
                           key_points: KeyPoints | None = None, logs: Logs | None = None) -> dict:
    """The episodes of one agent and family as a CARLA Leaderboard 1.0 checkpoint (``result.json``).

    Reproduces ``leaderboard/utils/statistics_manager.py`` (the final ``leaderboard-1.0``
    branch, ``compute_global_statistics`` and ``save_global_record``): records sorted by
    (route_id, k, seed); each route's length is its key points' (``key_points``: route id ->
    the route file's waypoints, m; the record's ``length`` where not given); a crashed episode
    has the status 'Failed - Agent crashed' or 'Failed - Simulation crashed'
    (:func:`~icrsumo.scoring.leaderboard.route_status`) and, where ``logs`` holds its log of
    the steps up to the crash, that log's RC, IS, DS, infractions and duration by these rules
    (the criteria's partial scores, as the leaderboard keeps them), else RC 0, IS 1, DS 0 (no
    criterion recorded anything); the global scores are means over
    *every* record, with the sample standard deviation; each infraction rate is the sum over
    records with RC > 0 of the record's count / (RC / 100 x route km); every record that is
    not 'Completed' is in ``meta.exceptions`` (absent when there is none). ``entry_status``:
    'Crashed' (not eligible) when a simulation crashed, else 'Finished with agent errors' when
    any record's status names the agent (as the leaderboard's substring test does:
    deviations, timeouts, blocks and agent crashes included), else 'Finished'. The global
    ``meta`` also holds ``total_length`` (m) and ``duration_game`` (s), summed, and
    ``duration_system`` -1 (icrsumo does not time episodes by wall clock; -1 is the
    leaderboard's value for a duration it was not given). The leaderboard stops at a simulation
    crash; here every record is in the file and in the global record."""
    import numpy as np  # here: the command line reads the registry without numpy

    mine = crash_scored(agent_records(records, agent, family), logs, LB1.score)
    recs = [_lb_record(r, i, lb_route_length(r, key_points)) for i, r in enumerate(mine)]
    n = len(recs)
    infr = _rates(recs)
    scores = {"score_route": 0.0, "score_penalty": 0.0, "score_composed": 0.0}
    std: dict[str, Any] = {k: "NaN" for k in scores}
    if n:
        cols = {k: [rec["scores"][k] for rec in recs] for k in scores}
        scores = {k: round(float(np.mean(v)), 6) for k, v in cols.items()}
        if n > 1:
            std = {k: round(float(np.std(v, ddof=1)), 6) for k, v in cols.items()}
    exceptions = [[rec["route_id"], rec["index"], rec["status"]] for rec in recs
                  if rec["status"] != "Completed"]
    meta: dict[str, Any] = {"exceptions": exceptions} if exceptions else {}
    meta.update({"total_length": round(sum(rec["meta"]["route_length"] for rec in recs), 6),
                 "duration_game": round(sum(r.duration for r in mine), 3), "duration_system": -1})
    global_record = {
        "route_id": -1,
        "index": -1,
        "status": "Failed" if exceptions else "Completed",
        "infractions": infr,
        "scores": scores,
        "meta": meta,
        "scores_std_dev": std,
    }
    values = [f"{scores['score_composed']:.3f}", f"{scores['score_route']:.3f}",
              f"{scores['score_penalty']:.3f}"] + [f"{infr[k]:.3f}" for k in LB_INFRACTIONS]
    entry, eligible = _entry_status([rec["status"] for rec in recs])
    return {
        "_checkpoint": {"global_record": global_record, "progress": [n, n], "records": recs},
        "entry_status": entry,
        "eligible": eligible,
        "sensors": [],
        "values": values,
        "labels": list(LABELS),
    }


# --------------------------------------------------------------------------- the rule set
class Leaderboard1(Scoring):
    """CARLA Leaderboard 1.0's rules (this module's docstring)."""

    name = "lb1"
    title = "CARLA Leaderboard 1.0 (branch leaderboard-1.0: statistics_manager.py, atomic_criteria.py)"
    rules = LB1_RULES

    def counted_collisions(self, log: EpisodeLog) -> list[Event]:
        return counted_collisions(log)

    def time_budget(self, route_length: float) -> float:
        """The route timeout: ``int(0.8 s/m x route length + 5 s)``."""
        return route_timeout(route_length)

    def leaderboard_file(self, records: Iterable[EpisodeRecord], agent: str, family: str,
                         key_points: KeyPoints | None = None, logs: Logs | None = None) -> dict:
        return leaderboard_checkpoint(records, agent, family, key_points, logs)


#: the Leaderboard 1.0 rule set (registered as ``lb1`` by :mod:`icrsumo.scoring`)
LB1 = Leaderboard1()
