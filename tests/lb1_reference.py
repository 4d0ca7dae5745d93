"""A test oracle: CARLA Leaderboard 1.0's route scoring transcribed in the leaderboard's own
shape, independently of icrsumo.scoring's rule code, to score a recorded episode log, and its
results file (the final commit of branch ``leaderboard-1.0``) built from stored records.

One class per criterion of scenario_runner's ``atomic_criteria.py`` (branch ``leaderboard-1.0``)
as ``route_scenario.py`` builds them, each with an ``update()`` per tick (a logged step) and the
collision sensor's callback before the criteria tick; ``compute_route_statistics`` as in
``leaderboard/utils/statistics_manager.py``. The map is what the log recorded: the route
points (icrsumo's dense route of the log's polyline) and the per-step lane bits; everything
else is the leaderboard's arithmetic, written here again on purpose.

The results file (:func:`results_file`): ``compute_route_length``, the route record
``compute_route_statistics`` registers for a stored episode (:func:`route_record`; for a
route whose agent crashed, over the criteria's partial run: :func:`crash_statistics`),
``compute_global_statistics`` and ``save_global_record``, and the route loop of
``leaderboard_evaluator.py`` that decides ``entry_status`` (a simulation crash ends the run).
"""

from __future__ import annotations

import math

from icrsumo.core.types import EpisodeLog, EpisodeRecord
from icrsumo.scoring.route import dense_route

PENALTY_COLLISION_PEDESTRIAN = 0.50
PENALTY_COLLISION_VEHICLE = 0.60
PENALTY_COLLISION_STATIC = 0.65
PENALTY_TRAFFIC_LIGHT = 0.70
PENALTY_STOP = 0.80


class Route:
    def __init__(self, log: EpisodeLog) -> None:
        r = dense_route(log)
        self.points = list(zip(r.x, r.y))
        self.forward = list(zip(r.fx, r.fy))
        self.accum = [0.0]
        for a, b in zip(self.points, self.points[1:]):
            self.accum.append(self.accum[-1] + math.sqrt((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2))


def _dot_passed(route: Route, index: int, loc) -> bool:
    (wx, wy), (fx, fy) = route.points[index], route.forward[index]
    return (loc[0] - wx) * fx + (loc[1] - wy) * fy > 0


class RouteCompletionTest:
    DISTANCE_THRESHOLD = 10.0
    WINDOWS_SIZE = 2

    def __init__(self, route: Route) -> None:
        self.route = route
        self._current_index = 0
        self._percentage_route_completed = 0.0
        self.success = False

    def update(self, loc) -> str:
        """The tick's status: the completing tick sets the test's SUCCESS but returns RUNNING;
        the next one returns SUCCESS (and the route ends there)."""
        if self.success:
            return "SUCCESS"
        n = len(self.route.points)
        for index in range(self._current_index, min(self._current_index + self.WINDOWS_SIZE + 1, n)):
            if _dot_passed(self.route, index, loc):
                self._current_index = index
                self._percentage_route_completed = 100.0 * self.route.accum[index] / self.route.accum[-1]
        tx, ty = self.route.points[-1]
        if self._percentage_route_completed > 99.0 and math.sqrt((loc[0] - tx) ** 2 + (loc[1] - ty) ** 2) \
                < self.DISTANCE_THRESHOLD:
            self.success = True
            self._percentage_route_completed = 100
        return "RUNNING"


class InRouteTest:
    MAX_ROUTE_PERCENTAGE = 30
    WINDOWS_SIZE = 5

    def __init__(self, route: Route, offroad_max: float = 30) -> None:
        self.route = route
        self._offroad_max = offroad_max
        self._offroad_min = offroad_max / 2
        self._current_index = 0
        self._out_route_distance = 0.0
        self._in_safe_route = True
        self.failure = False

    def update(self, loc) -> None:
        if self.failure:
            return
        off_route = True
        shortest, closest = float("inf"), -1
        n = len(self.route.points)
        for index in range(self._current_index, min(self._current_index + self.WINDOWS_SIZE + 1, n)):
            wx, wy = self.route.points[index]
            distance = math.sqrt((loc[0] - wx) ** 2 + (loc[1] - wy) ** 2)
            if distance <= shortest:
                closest, shortest = index, distance
        if shortest < self._offroad_max:
            off_route = False
            self._in_safe_route = bool(shortest < self._offroad_min)
        if self._current_index != closest:
            new_dist = self.route.accum[closest] - self.route.accum[self._current_index]
            if not self._in_safe_route:
                self._out_route_distance += new_dist
                if 100 * self._out_route_distance / self.route.accum[-1] > self.MAX_ROUTE_PERCENTAGE:
                    off_route = True
            self._current_index = closest
        if off_route:
            self.failure = True


class OutsideRouteLanesTest:
    WINDOWS_SIZE = 3

    def __init__(self, route: Route) -> None:
        self.route = route
        self._current_index = 0
        self._total_distance = 0.0
        self._wrong_distance = 0.0

    def update(self, loc, outside_or_wrong: bool) -> None:
        n = len(self.route.points)
        for index in range(self._current_index + 1, min(self._current_index + self.WINDOWS_SIZE + 1, n)):
            if _dot_passed(self.route, index, loc):
                a, b = self.route.points[self._current_index], self.route.points[index]
                new_dist = math.sqrt((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2)
                self._current_index = index
                self._total_distance += new_dist
                if outside_or_wrong:
                    self._wrong_distance += new_dist

    def percentage(self) -> float | None:
        if self._wrong_distance > 0:
            return self._wrong_distance / self._total_distance * 100
        return None


class CollisionTest:
    MIN_AREA_OF_COLLISION = 3
    MAX_AREA_OF_COLLISION = 5
    MAX_ID_TIME = 5

    def __init__(self) -> None:
        self.registered_collisions: list = []
        self.last_id = None
        self.collision_time = None
        self.events: list[str] = []

    def count_collision(self, now: float, loc, kind: str, other_id) -> None:
        if self.last_id == other_id:
            return
        for cx, cy in self.registered_collisions:
            if math.sqrt((loc[0] - cx) ** 2 + (loc[1] - cy) ** 2) <= self.MIN_AREA_OF_COLLISION:
                return
        self.events.append(kind)
        self.collision_time = now
        self.registered_collisions.append(loc)
        if other_id != 0:
            self.last_id = other_id

    def update(self, now: float, loc) -> None:
        self.registered_collisions = [(cx, cy) for cx, cy in self.registered_collisions
                                      if math.sqrt((loc[0] - cx) ** 2 + (loc[1] - cy) ** 2)
                                      <= self.MAX_AREA_OF_COLLISION]
        if self.last_id and now - self.collision_time > self.MAX_ID_TIME:
            self.last_id = None


class ActorSpeedAboveThresholdTest:
    def __init__(self, speed_threshold: float = 0.1, below_threshold_max_time: float = 180.0) -> None:
        self._speed_threshold = speed_threshold
        self._below_threshold_max_time = below_threshold_max_time
        self._time_last_valid_state = None
        self.failure = False

    def update(self, now: float, speed: float) -> None:
        if speed < self._speed_threshold and self._time_last_valid_state is not None:
            if now - self._time_last_valid_state > self._below_threshold_max_time:
                self.failure = True
        else:
            self._time_last_valid_state = now


def score(log: EpisodeLog) -> dict:
    """The leaderboard's ``score_route``, ``score_penalty``, ``score_composed``, the reason
    the route ended ("completed", "route_deviation", "agent_blocked", "route_timeout" or None),
    ``events``: the criteria's penalised traffic events (one entry per event: collisions,
    red lights, stop signs, and "outside_route_lanes" when the ego went outside them) and
    ``duration``: the simulated time (s) from the first tick to the last one run."""
    route = Route(log)
    completion, in_route = RouteCompletionTest(route), InRouteTest(route)
    lanes, collisions, blocked = OutsideRouteLanesTest(route), CollisionTest(), ActorSpeedAboveThresholdTest()
    timeout = int(0.8 * route.accum[-1] + 5.0)
    red_lights = stops = 0
    half = 0.5 * log.step_length + 1e-6
    ended = None
    for i, now in enumerate(log.t):
        loc = (log.x[i], log.y[i])
        for e in log.events:  # the sensor's callbacks of this tick
            if abs(e.t - now) <= half and (i == 0 or abs(e.t - log.t[i - 1]) > abs(e.t - now)):
                if e.kind in ("collision_vehicle", "collision_pedestrian"):
                    collisions.count_collision(now, loc, e.kind, e.other or 0)
                elif e.kind == "collision_static":
                    collisions.count_collision(now, loc, e.kind, 0)
                elif e.kind == "red_light":
                    red_lights += 1
                elif e.kind == "stop_sign":
                    stops += 1
        status = completion.update(loc)
        lanes.update(loc, bool(log.outside[i] & 3))
        collisions.update(now, loc)
        in_route.update(loc)
        blocked.update(now, log.speed[i])
        if status == "SUCCESS":
            ended = "completed"
        elif in_route.failure:
            ended = "route_deviation"
        elif blocked.failure:
            ended = "agent_blocked"
        elif now - log.t[0] > timeout:
            ended = "route_timeout"
        if ended:
            break
    # compute_route_statistics
    score_penalty = 1.0
    for kind in collisions.events:
        score_penalty *= {"collision_static": PENALTY_COLLISION_STATIC, "collision_pedestrian":
                          PENALTY_COLLISION_PEDESTRIAN, "collision_vehicle": PENALTY_COLLISION_VEHICLE}[kind]
    score_penalty *= PENALTY_TRAFFIC_LIGHT ** red_lights * PENALTY_STOP ** stops
    pct = lanes.percentage()
    if pct is not None:
        score_penalty *= 1 - pct / 100
    score_route = 100.0 if completion.success else completion._percentage_route_completed
    events = [*collisions.events, *["red_light"] * red_lights, *["stop_sign"] * stops,
              *(["outside_route_lanes"] if pct is not None else [])]
    duration = now - log.t[0] if log.t else 0.0  # GameTime from the first tick to the last one run
    return {"score_route": score_route, "score_penalty": score_penalty,
            "score_composed": max(score_route * score_penalty, 0.0), "ended": ended, "events": events,
            "duration": duration}


# ------------------------------------------------------------------ the results file
INFRACTION_KEYS = ("collisions_pedestrian", "collisions_vehicle", "collisions_layout", "red_light",
                   "stop_infraction", "outside_route_lanes", "route_dev", "route_timeout", "vehicle_blocked")
#: the traffic event of a stored infraction kind: (infraction key, penalty; None: the percentage's)
EVENTS = {"collision_pedestrian": ("collisions_pedestrian", PENALTY_COLLISION_PEDESTRIAN),
          "collision_vehicle": ("collisions_vehicle", PENALTY_COLLISION_VEHICLE),
          "collision_static": ("collisions_layout", PENALTY_COLLISION_STATIC),
          "red_light": ("red_light", PENALTY_TRAFFIC_LIGHT), "stop_sign": ("stop_infraction", PENALTY_STOP),
          "outside_route_lanes": ("outside_route_lanes", None)}
#: how icrsumo's terminations map onto the criteria that end a route: (infraction key, failure)
ENDINGS = {"route_deviation": ("route_dev", "Agent deviated from the route"),
           "route_timeout": ("route_timeout", "Agent timed out"),
           "agent_blocked": ("vehicle_blocked", "Agent got blocked"),
           "stuck": ("vehicle_blocked", "Agent got blocked")}


def compute_route_length(trajectory) -> float:
    """The sum of the straight distances between consecutive points of the route's trajectory."""
    length = 0.0
    for a, b in zip(trajectory, trajectory[1:]):
        length += math.sqrt(sum((q - p) ** 2 for p, q in zip(a, b)))
    return length


def crash_message(rec: EpisodeRecord) -> str:
    """The evaluator's ``crash_message`` for a stored episode: "Simulation crashed" when SUMO
    died in it (termination sim_error) or, for a crashed episode, when SUMO failed to start or
    the worker process died (icrsumo's convention); "Agent crashed" for any other crash; ""."""
    if rec.status == "crashed":
        sim = rec.message.startswith(("SimulatorError:", "WorkerDied:"))
        return "Simulation crashed" if sim else "Agent crashed"
    return "Simulation crashed" if rec.termination == "sim_error" else ""


def route_record(rec: EpisodeRecord, index: int, route_id: str, trajectory, log: EpisodeLog | None = None
                 ) -> dict:
    """``compute_route_statistics`` for a stored episode: its infractions are the criteria's
    traffic events, its termination the criterion that ended it. A crashed episode: with
    ``log`` (its steps up to the crash) the criteria run over that log until the crash
    (:func:`crash_statistics`), without one nothing was recorded."""
    if rec.status == "crashed" and log is not None:
        return crash_statistics(rec, index, route_id, trajectory, log)
    record = {"route_id": route_id, "index": index, "status": "Started",
              "infractions": {k: [] for k in INFRACTION_KEYS},
              "scores": {"score_route": 0, "score_penalty": 0, "score_composed": 0}, "meta": {}}
    failure = crash_message(rec)
    score_penalty, score_route, target_reached = 1.0, 0.0, False
    record["meta"]["duration_system"] = -1
    record["meta"]["duration_game"] = rec.duration
    record["meta"]["route_length"] = compute_route_length(trajectory)
    if rec.status != "crashed":
        for kind, factor in rec.infractions:
            key, penalty = EVENTS[kind]
            score_penalty *= factor if penalty is None else penalty
            record["infractions"][key].append(kind)
        if rec.termination in ENDINGS:
            key, failure = ENDINGS[rec.termination]
            record["infractions"][key].append(rec.termination)
        if rec.termination == "completed":
            score_route, target_reached = 100.0, True
        else:
            score_route = rec.rc
    record["scores"] = {"score_route": score_route, "score_penalty": score_penalty,
                        "score_composed": max(score_route * score_penalty, 0.0)}
    record["status"] = "Completed" if target_reached else "Failed" + (" - " + failure if failure else "")
    return record


def crash_statistics(rec: EpisodeRecord, index: int, route_id: str, trajectory, log: EpisodeLog) -> dict:
    """``compute_route_statistics`` for a route whose agent crashed (``failure`` "Agent crashed"):
    the criteria ticked over the log's steps (:func:`score`), their traffic events the
    infractions, a criterion that ended the route overriding the failure (as
    ``compute_route_statistics`` overrides it), ``duration_game`` the simulated time run."""
    s = score(log)
    record = {"route_id": route_id, "index": index, "status": "Started",
              "infractions": {k: [] for k in INFRACTION_KEYS},
              "scores": {"score_route": 0, "score_penalty": 0, "score_composed": 0},
              "meta": {"duration_system": -1, "duration_game": s["duration"],
                       "route_length": compute_route_length(trajectory)}}
    failure = crash_message(rec)
    for kind in s["events"]:
        record["infractions"][EVENTS[kind][0]].append(kind)
    if s["ended"] in ENDINGS:
        key, failure = ENDINGS[s["ended"]]
        record["infractions"][key].append(s["ended"])
    record["scores"] = {k: s[k] for k in ("score_route", "score_penalty", "score_composed")}
    target_reached = s["ended"] == "completed"
    record["status"] = "Completed" if target_reached else "Failed" + (" - " + failure if failure else "")
    return record


def compute_global_statistics(records: list[dict], total_routes: int) -> dict:
    glob = {"route_id": -1, "index": -1, "status": "Completed",
            "infractions": {k: [] for k in INFRACTION_KEYS},
            "scores": {"score_route": 0, "score_penalty": 0, "score_composed": 0},
            "meta": {"total_length": 0, "duration_system": 0, "duration_game": 0},
            "scores_std_dev": {"score_route": 0, "score_penalty": 0, "score_composed": 0}}
    if not records:
        return glob
    for record in records:
        for k in glob["scores"]:
            glob["scores"][k] += record["scores"][k]
        for k in ("duration_game", "duration_system"):
            glob["meta"][k] += record["meta"][k]
        glob["meta"]["total_length"] += record["meta"]["route_length"]
        for k in INFRACTION_KEYS:
            if isinstance(glob["infractions"][k], list):
                glob["infractions"][k] = 0
            if record["scores"]["score_route"] == 0:  # the vehicle has not moved
                continue
            km = record["scores"]["score_route"] / 100 * record["meta"]["route_length"] / 1000.0
            glob["infractions"][k] += len(record["infractions"][k]) / km
        if record["status"] != "Completed":
            glob["status"] = "Failed"
            glob["meta"].setdefault("exceptions", []).append(
                (record["route_id"], record["index"], record["status"]))
    for k in glob["scores"]:
        glob["scores"][k] /= float(total_routes)
    if total_routes == 1:
        glob["scores_std_dev"] = {k: "NaN" for k in glob["scores_std_dev"]}
    else:
        for k in glob["scores_std_dev"]:
            sq = sum((record["scores"][k] - glob["scores"][k]) ** 2 for record in records)
            glob["scores_std_dev"][k] = math.sqrt(sq / float(total_routes - 1))
    return glob


def save_global_record(data: dict, glob: dict, total_routes: int) -> None:
    data["_checkpoint"]["global_record"] = glob
    data["values"] = ["{:.3f}".format(glob["scores"][k])
                      for k in ("score_composed", "score_route", "score_penalty")] + [
        "{:.3f}".format(glob["infractions"][k]) for k in INFRACTION_KEYS]
    data["labels"] = ["Avg. driving score", "Avg. route completion", "Avg. infraction penalty",
                      "Collisions with pedestrians", "Collisions with vehicles", "Collisions with layout",
                      "Red lights infractions", "Stop sign infractions", "Off-road infractions",
                      "Route deviations", "Route timeouts", "Agent blocked"]
    records, progress = data["_checkpoint"]["records"], data["_checkpoint"]["progress"]
    entry, eligible = "Finished", True
    if len(records) != total_routes or progress[0] != progress[1]:
        entry, eligible = "Finished with missing data", False
    elif any("Agent" in record["status"] for record in records):
        entry = "Finished with agent errors"
    data["entry_status"], data["eligible"] = entry, eligible


def results_file(route_records: list[dict]) -> dict:
    """The leaderboard evaluator's run over routes whose statistics are ``route_records`` (in
    the order run): each is saved with entry_status 'Started' (or 'Crashed' after a simulation
    crash, which ends the run there, without a global record); after the last route, the global
    record and the final entry_status."""
    total = len(route_records)
    data = {"sensors": [], "values": [], "labels": [], "entry_status": "", "eligible": "",
            "_checkpoint": {"progress": [0, total], "records": [], "global_record": {}}}
    for i, record in enumerate(route_records):
        data["_checkpoint"]["records"].append(record)
        crashed = record["status"] == "Failed - Simulation crashed"
        data["entry_status"], data["eligible"] = ("Crashed" if crashed else "Started"), False
        if crashed:
            return data
        data["_checkpoint"]["progress"] = [i + 1, total]
    save_global_record(data, compute_global_statistics(route_records, total), total)
    return data


def leaderboard_file(records: list[EpisodeRecord], key_points: dict | None = None,
                     logs: dict | None = None) -> dict:
    """:func:`results_file` of one agent's and family's stored episodes, run in icrsumo's order
    (route id, k, seed); a route's trajectory is its key points (``key_points``: route id ->
    points) or, where they are not known, a straight line of the record's length; ``logs``:
    (agent, route id, family, k, seed) -> the stored log of a crashed episode that has one."""
    ordered = sorted(records, key=lambda r: (r.route_id, r.k, r.seed))
    return results_file([
        route_record(r, i, f"RouteScenario_{r.route_id}_{r.family}_{r.k}",
                     (key_points or {}).get(r.route_id) or [(0.0, 0.0), (r.length, 0.0)],
                     (logs or {}).get((r.agent, r.route_id, r.family, r.k, r.seed)))
        for i, r in enumerate(ordered)])


def _near(a, b, tol: float) -> bool:
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    return abs(a - b) <= tol * max(1.0, abs(b))


def differences(mine: dict, ref: dict, tol: float = 1e-4) -> list[str]:
    """Where icrsumo's results file ``mine`` differs from the transcription's ``ref``: statuses,
    infraction counts, per-route and global scores and lengths, rates (relative to values
    above 1, absolute below, within ``tol``), ``values``, exceptions, entry status. Not
    compared: the infraction messages (icrsumo words its own) and ``duration_system`` (icrsumo
    keeps no wall clock). When ``ref`` ended at a simulation crash, its records are compared
    with the first ones of ``mine`` and its global record is not (icrsumo writes every route)."""
    out = []
    for k in ("entry_status", "eligible", "sensors"):
        if mine[k] != ref[k]:
            out.append(f"{k}: {mine[k]!r} != {ref[k]!r}")
    rr, mr = ref["_checkpoint"]["records"], mine["_checkpoint"]["records"]
    stopped = ref["entry_status"] == "Crashed"
    if len(mr) < len(rr) or (not stopped and len(mr) != len(rr)):
        out.append(f"{len(mr)} records != {len(rr)}")
    for m, r in zip(mr, rr):
        where = f"record {r['index']}"
        for k in ("route_id", "index", "status"):
            if m[k] != r[k]:
                out.append(f"{where} {k}: {m[k]!r} != {r[k]!r}")
        counts = [{k: len(v) for k, v in x["infractions"].items()} for x in (m, r)]
        if counts[0] != counts[1]:
            out.append(f"{where} infractions: {counts[0]} != {counts[1]}")
        for k, v in r["scores"].items():
            if not _near(m["scores"][k], v, tol):
                out.append(f"{where} {k}: {m['scores'][k]} != {v}")
        for k in ("route_length", "duration_game"):
            if not _near(m["meta"][k], r["meta"][k], tol):
                out.append(f"{where} meta.{k}: {m['meta'][k]} != {r['meta'][k]}")
    if stopped:
        return out
    if mine["labels"] != ref["labels"]:
        out.append(f"labels: {mine['labels']!r} != {ref['labels']!r}")
    if mine["_checkpoint"]["progress"] != ref["_checkpoint"]["progress"]:
        out.append(f"progress: {mine['_checkpoint']['progress']} != {ref['_checkpoint']['progress']}")
    mg, rg = mine["_checkpoint"]["global_record"], ref["_checkpoint"]["global_record"]
    for k in ("route_id", "index", "status"):
        if mg[k] != rg[k]:
            out.append(f"global {k}: {mg[k]!r} != {rg[k]!r}")
    for part in ("infractions", "scores", "scores_std_dev"):
        for k, v in rg[part].items():
            if not _near(mg[part][k], v, tol):
                out.append(f"global {part}.{k}: {mg[part][k]} != {v}")
    for k in ("total_length", "duration_game"):
        if not _near(mg["meta"][k], rg["meta"][k], tol):
            out.append(f"global meta.{k}: {mg['meta'][k]} != {rg['meta'][k]}")
    want = [list(e) for e in rg["meta"]["exceptions"]] if "exceptions" in rg["meta"] else None
    got = mg["meta"].get("exceptions")
    if got != want:
        out.append(f"global meta.exceptions: {got!r} != {want!r}")
    for i, (a, b) in enumerate(zip(mine["values"], ref["values"])):
        if not _near(float(a), float(b), 1e-3 + tol):
            out.append(f"values[{i}]: {a} != {b}")
    if len(mine["values"]) != len(ref["values"]):
        out.append(f"{len(mine['values'])} values != {len(ref['values'])}")
    return out
