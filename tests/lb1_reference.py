"""A test oracle: CARLA Leaderboard 1.0's route scoring transcribed in the leaderboard's own
shape, independently of icrsumo.scoring's rule code, to score a recorded episode log.

One class per criterion of scenario_runner's ``atomic_criteria.py`` (branch ``leaderboard-1.0``)
as ``route_scenario.py`` builds them, each with an ``update()`` per tick (a logged step) and the
collision sensor's callback before the criteria tick; ``compute_route_statistics`` as in
``leaderboard/utils/statistics_manager.py``. The map is what the log recorded: the route
points (icrsumo's dense route of the log's polyline) and the per-step lane bits; everything
else is the leaderboard's arithmetic, written here again on purpose.
"""

from __future__ import annotations

import math

from icrsumo.core.types import EpisodeLog
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

    def update(self, loc) -> None:
        if self.success:
            return
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
    """The leaderboard's ``score_route``, ``score_penalty``, ``score_composed`` and the reason
    the route ended ("completed", "route_deviation", "agent_blocked", "route_timeout" or None)."""
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
        completion.update(loc)
        lanes.update(loc, bool(log.outside[i] & 3))
        collisions.update(now, loc)
        in_route.update(loc)
        blocked.update(now, log.speed[i])
        if completion.success:
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
    return {"score_route": score_route, "score_penalty": score_penalty,
            "score_composed": max(score_route * score_penalty, 0.0), "ended": ended}
