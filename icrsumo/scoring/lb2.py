"""CARLA Leaderboard 2.0's scoring (``lb2``), whole: route criteria, collision counting, step
budget, per-route scores and the results file.

Reproduces the 2.0 branches of ``leaderboard/utils/statistics_manager.py`` and scenario_runner's
``atomic_criteria.py`` where they apply to icrsumo's routes (the per-route scores are computed as
:mod:`icrsumo.scoring.lb1` describes, with these differences): RC rounded to 2 decimals,
OutsideRouteLanesTest with 2.0's lane rules, its ``CollisionTest`` (:class:`CollisionCounter2`:
one remembered place within 5 m, none while the ego is below 0.1 m/s), MinimumSpeedRouteTest's
factor ``1 - 0.3 (1 - pct / 100)`` per checkpoint below 100 % of the other vehicles' mean speed
(4 checkpoints), and the route timeout of RouteTimeoutBehavior (scenario_runner's ``timer.py``;
:mod:`icrsumo.scoring.criteria`). Scenario-specific criteria (yield to an emergency vehicle,
scenario timeouts) have no counterpart here.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

from icrsumo.core.types import EpisodeLog, EpisodeRecord, Event, Infraction
from icrsumo.core.vocab import EventKind

from .base import KeyPoints, Scoring
from .criteria import (
    EPS,
    MIN_TIMEOUT_LB2,
    OFF_LANES_LB2,
    WRONG_LANE_LB2,
    RouteRules,
    TerminationMonitor,
    events_by_step,
)
from .leaderboard import LABELS, Logs, agent_records, crash_scored, record_infractions, route_name
from .penalties import MAX_ID_TIME, contacts

#: Leaderboard 2.0's route criteria (scenario_runner's and leaderboard's 2.0 branches):
#: RouteCompletionTest rounds to 2 decimals, RouteTimeoutBehavior, MinimumSpeedRouteTest(checkpoints=4)
LB2_RULES = RouteRules("lb2", OFF_LANES_LB2 | WRONG_LANE_LB2, 2, "progress", 4)

#: MinimumSpeedRouteTest's penalty value (2.0: PENALTY_PERC_DICT[MIN_SPEED_INFRACTION] = [0.7, 'decreases'])
MIN_SPEED_FACTOR = 0.7


class CollisionCounter2:
    """Leaderboard 2.0's ``CollisionTest``, step by step (see
    :class:`~icrsumo.scoring.lb1.CollisionCounter`): a contact is ignored when it is with the
    remembered actor, within 5 m of the one remembered place, or while the ego is below
    0.1 m/s; a counted one replaces the place and time (and the actor, unless it is the static
    layout). The place is forgotten once the ego is more than 5 m from it, the actor 5 s after
    the last counted collision."""

    RADIUS = 5.0
    MIN_SPEED = 0.1

    def __init__(self) -> None:
        self.place: tuple[float, float] | None = None
        self.last_id: str | None = None
        self.last_t = 0.0

    def _near(self, x: float, y: float) -> bool:
        """Whether the ego centre (m) is within 5 m of the remembered place."""
        p = self.place
        return p is not None and math.sqrt((x - p[0]) ** 2 + (y - p[1]) ** 2) <= self.RADIUS

    def step(self, t: float, x: float, y: float, speed: float, events: Sequence[Event]) -> list[Event]:
        out: list[Event] = []
        for e, actor in contacts(events, self.last_id):
            if self._near(x, y):
                continue
            if speed < self.MIN_SPEED:
                continue
            out.append(e)
            self.last_t, self.place = t, (x, y)
            if actor:
                self.last_id = actor
        if self.place is not None and not self._near(x, y):
            self.place = None
        if self.last_id is not None and t - self.last_t > MAX_ID_TIME + EPS:
            self.last_id = None
        return out


def counted_collisions_lb2(log: EpisodeLog) -> list[Event]:
    """The collision events of ``log`` that Leaderboard 2.0's CollisionTest counts."""
    by_step, _ = events_by_step(log)
    counter = CollisionCounter2()
    out: list[Event] = []
    for i, evs in enumerate(by_step):
        out += counter.step(log.t[i], log.x[i], log.y[i], log.speed[i], evs)
    return out


# --------------------------------------------------------------------------- the results file
#: Leaderboard 2.0's infraction keys (statistics_manager.py's PENALTY_NAME_DICT and route_timeout)
LB2_INFRACTIONS = ("collisions_layout", "collisions_pedestrian", "collisions_vehicle", "red_light",
                   "stop_infraction", "outside_route_lanes", "min_speed_infractions",
                   "yield_emergency_vehicle_infractions", "scenario_timeouts", "route_dev", "vehicle_blocked",
                   "route_timeout")
_LB2_VALUE_KEYS = ("collisions_pedestrian", "collisions_vehicle", "collisions_layout", "red_light",
                   "stop_infraction", "outside_route_lanes", "route_dev", "route_timeout",
                   "vehicle_blocked", "yield_emergency_vehicle_infractions", "scenario_timeouts",
                   "min_speed_infractions")
_LB2_LABELS = [*LABELS, "Yield emergency vehicles infractions", "Scenario timeouts",
               "Min speed infractions"]


def _wording(r: EpisodeRecord, kind: str, factor: float) -> tuple[str, str] | None:
    """2.0's outside-lanes entry (metres and percentage) and minimum-speed entry (the
    checkpoint's percentage); other kinds are penalised events."""
    if kind == EventKind.OUTSIDE_ROUTE_LANES:
        return "outside_route_lanes", (f"Agent went outside its route lanes for about {r.outside_m:.3f} "
                                       f"meters ({100.0 * (1.0 - factor):.2f}% of the completed route)")
    if kind == EventKind.MIN_SPEED:
        value = 100.0 * (1.0 - (1.0 - factor) / 0.3)
        return "min_speed_infractions", f"Average speed is {value:.2f}% of the surrounding traffic's one"
    return None


def _lb2_record(r: EpisodeRecord, index: int) -> dict:
    status, infr = record_infractions(r, LB2_INFRACTIONS, _wording)
    if status == "Completed" and not any(infr.values()):
        status = "Perfect"
    return {
        "index": index,
        "route_id": route_name(r),
        "status": status,
        "num_infractions": sum(len(v) for v in infr.values()),
        "infractions": infr,
        "scores": {"score_route": round(r.rc, 6), "score_penalty": round(r.is_, 6),
                   "score_composed": round(max(r.ds, 0.0), 6)},
        "meta": {"route_length": round(r.length, 3), "duration_game": round(r.duration, 3),
                 "duration_system": -1},
    }


def leaderboard_checkpoint_lb2(records: Iterable[EpisodeRecord], agent: str, family: str,
                               logs: Logs | None = None) -> dict:
    """The episodes of one agent and family as a CARLA Leaderboard 2.0 results file.

    Reproduces 2.0's ``statistics_manager.py`` (``compute_global_statistics``): statuses
    'Perfect' (completed without any infraction), 'Completed' and 'Failed - ...'; the means
    over every record rounded to 6 decimals and the sample standard deviations (around the
    rounded means) to 3; infractions pooled over the routes: count / max(sum of RC / 100 x
    route km, 0.001), except ``outside_route_lanes``, which is the km of route advance made off
    the lanes; the global status drops Perfect -> Completed -> Failed; ``entry_status``
    'Crashed' (not eligible) when a simulation crashed, else 'Finished'; ``duration_system`` is
    -1 (not timed by wall clock). A crashed episode whose log of the steps up to the crash
    ``logs`` holds has that log's RC, IS, DS and infractions by 2.0's rules (what its criteria
    had computed when the agent crashed, as 2.0's ``compute_route_statistics`` keeps them),
    status 'Failed - Agent crashed'; one without a log is scored as stored (RC 0, DS 0)."""
    mine = crash_scored(agent_records(records, agent, family), logs, LB2.score)
    recs = [_lb2_record(r, i) for i, r in enumerate(mine)]
    n = len(recs)
    keys = ("score_composed", "score_route", "score_penalty")
    means = {k: 0.0 for k in keys}
    for rec in recs:
        for k in keys:
            means[k] += rec["scores"][k] / n
    means = {k: round(v, 6) for k, v in means.items()}
    std = {k: 0.0 for k in keys}
    if n > 1:
        std = {k: round(math.sqrt(sum((rec["scores"][k] - means[k]) ** 2 for rec in recs) / (n - 1)), 3)
               for k in keys}
    km = max(sum(r.length / 1000.0 * r.rc / 100.0 for r in mine), 0.001)
    infr = {}
    for k in LB2_INFRACTIONS:
        if k == "outside_route_lanes":
            infr[k] = round(sum(r.outside_m for r in mine if any(kind == EventKind.OUTSIDE_ROUTE_LANES
                                                                 for kind, _ in r.infractions)) / 1000.0, 3)
        else:
            infr[k] = round(sum(len(rec["infractions"][k]) for rec in recs) / km, 3)
    status, exceptions = "Perfect", []
    for rec in recs:
        if "Failed" in rec["status"]:
            exceptions.append([rec["route_id"], rec["index"], rec["status"]])
            status = "Failed"
        elif status == "Perfect" and rec["status"] != "Perfect":
            status = rec["status"]
    global_record = {
        "index": -1, "route_id": -1, "status": status, "infractions": infr,
        "scores_mean": means, "scores_std_dev": std,
        "meta": {"total_length": round(sum(r.length for r in mine), 3),
                 "duration_game": round(sum(r.duration for r in mine), 3), "duration_system": -1,
                 "exceptions": exceptions},
    }
    values = [str(means["score_composed"]), str(means["score_route"]), str(means["score_penalty"])] + [
        str(infr[k]) for k in _LB2_VALUE_KEYS]
    crashed = any("Simulation crashed" in rec["status"] for rec in recs)
    return {
        "_checkpoint": {"global_record": global_record, "progress": [n, n], "records": recs},
        "entry_status": "Crashed" if crashed else "Finished",
        "eligible": not crashed,
        "sensors": [],
        "values": values,
        "labels": list(_LB2_LABELS),
    }


# --------------------------------------------------------------------------- the rule set
class Leaderboard2(Scoring):
    """CARLA Leaderboard 2.0's rules (this module's docstring)."""

    name = "lb2"
    title = ("CARLA Leaderboard 2.0 (its statistics_manager.py, atomic_criteria.py, "
             "RouteTimeoutBehavior), where it applies to icrsumo's routes")
    rules = LB2_RULES

    def counted_collisions(self, log: EpisodeLog) -> list[Event]:
        return counted_collisions_lb2(log)

    def time_budget(self, route_length: float) -> float:
        """RouteTimeoutBehavior's 300 s, plus the whole route driven at 10 % of a speed limit of
        at least 1 m/s (the timeout grows with the route advance; a bound, not the timeout)."""
        return MIN_TIMEOUT_LB2 + route_length / 0.1

    def route_infractions(self, log: EpisodeLog, mon: TerminationMonitor | None) -> list[Infraction]:
        """Outside route lanes (as 1.0), then MinimumSpeedRouteTest's factor
        ``1 - 0.3 (1 - pct / 100)`` for each checkpoint below 100 %."""
        out = super().route_infractions(log, mon)
        for i, value in enumerate(mon.min_speed if mon is not None else ()):
            if value < 100.0:
                factor = 1.0 - (1.0 - MIN_SPEED_FACTOR) * (1.0 - value / 100.0)
                out.append(Infraction(EventKind.MIN_SPEED, factor, log.t[-1], mon.progress,
                                      f"checkpoint {i + 1}: {value:.2f}%"))
        return out

    def leaderboard_file(self, records: Iterable[EpisodeRecord], agent: str, family: str,
                         key_points: KeyPoints | None = None, logs: Logs | None = None) -> dict:
        """2.0's file (its route length is the interpolated route's: ``key_points`` is not used;
        a crashed episode with a partial log in ``logs`` is scored from it)."""
        return leaderboard_checkpoint_lb2(records, agent, family, logs)


#: the Leaderboard 2.0 rule set (registered as ``lb2`` by :mod:`icrsumo.scoring`)
LB2 = Leaderboard2()
