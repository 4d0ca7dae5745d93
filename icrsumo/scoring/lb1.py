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
from icrsumo.core.vocab import EventKind

from .base import Scoring
from .criteria import EPS, OFF_LANES, WRONG_LANE, RouteRules, events_by_step, route_timeout
from .leaderboard import LABELS, agent_records, record_infractions, route_name
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


def _lb_record(r: EpisodeRecord, index: int) -> dict:
    status, infr = record_infractions(r, LB_INFRACTIONS, _wording)
    return {
        "route_id": route_name(r),
        "index": index,
        "status": status,
        "infractions": infr,
        "scores": {"score_route": r.rc, "score_penalty": r.is_, "score_composed": r.ds},
        "meta": {"route_length": r.length, "duration_game": r.duration, "duration_system": -1},
    }


def leaderboard_checkpoint(records: Iterable[EpisodeRecord], agent: str, family: str) -> dict:
    """The episodes of one agent and family as a CARLA Leaderboard 1.0 checkpoint (``result.json``).

    Reproduces ``leaderboard/utils/statistics_manager.py`` (branch ``leaderboard-1.0``,
    ``compute_global_statistics`` and ``save_global_record``): records sorted by (route_id, k,
    seed); the global scores are means over *every* record, crashed ones included (their scores
    are 0), with the sample standard deviation; each infraction rate is the sum over records of
    the record's count / max(RC / 100 x route km, 0.001); every record that is not 'Completed' is
    in ``meta.exceptions``. ``entry_status``: 'Crashed' (not eligible) when an episode's simulation
    crashed, else 'Finished with agent errors' when any record's status names the agent (as
    the leaderboard's substring test does: deviations, timeouts and blocks included), else
    'Finished'. The global ``meta`` also holds ``total_length`` (m) and ``duration_game`` (s),
    summed, and ``duration_system`` -1 (icrsumo does not time episodes by wall clock; -1 is the
    leaderboard's value for a duration it was not given)."""
    import numpy as np  # here: the command line reads the registry without numpy

    mine = agent_records(records, agent, family)
    recs = [_lb_record(r, i) for i, r in enumerate(mine)]
    n = len(recs)
    infr = {k: 0.0 for k in LB_INFRACTIONS}
    for r, rec in zip(mine, recs):
        km = max(r.rc / 100.0 * r.length / 1000.0, 0.001)
        for k in LB_INFRACTIONS:
            infr[k] += len(rec["infractions"][k]) / km
    infr = {k: round(v, 6) for k, v in infr.items()}
    scores = {"score_route": 0.0, "score_penalty": 0.0, "score_composed": 0.0}
    std: dict[str, Any] = {k: "NaN" for k in scores}
    if n:
        cols = {"score_route": [r.rc for r in mine], "score_penalty": [r.is_ for r in mine],
                "score_composed": [r.ds for r in mine]}
        scores = {k: round(float(np.mean(v)), 6) for k, v in cols.items()}
        if n > 1:
            std = {k: round(float(np.std(v, ddof=1)), 6) for k, v in cols.items()}
    exceptions = [[rec["route_id"], rec["index"], rec["status"]] for rec in recs
                  if rec["status"] != "Completed"]
    global_record = {
        "route_id": -1,
        "index": -1,
        "status": "Failed" if exceptions else "Completed",
        "infractions": infr,
        "scores": scores,
        "meta": {"exceptions": exceptions, "total_length": round(sum(r.length for r in mine), 2),
                 "duration_game": round(sum(r.duration for r in mine), 3), "duration_system": -1},
        "scores_std_dev": std,
    }
    values = [f"{scores['score_composed']:.3f}", f"{scores['score_route']:.3f}",
              f"{scores['score_penalty']:.3f}"] + [
        f"{infr[k]:.3f}" for k in ("collisions_pedestrian", "collisions_vehicle", "collisions_layout",
                                   "red_light", "stop_infraction", "outside_route_lanes", "route_dev",
                                   "route_timeout", "vehicle_blocked")]
    statuses = [rec["status"] for rec in recs]
    if "Failed - Simulation crashed" in statuses:
        entry, eligible = "Crashed", False
    elif any("Agent" in st for st in statuses):
        entry, eligible = "Finished with agent errors", True
    else:
        entry, eligible = "Finished", True
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

    def leaderboard_file(self, records: Iterable[EpisodeRecord], agent: str, family: str) -> dict:
        return leaderboard_checkpoint(records, agent, family)


#: the Leaderboard 1.0 rule set (registered as ``lb1`` by :mod:`icrsumo.scoring`)
LB1 = Leaderboard1()
