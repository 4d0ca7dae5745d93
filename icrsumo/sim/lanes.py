"""The lane facts of Leaderboard 1.0's ``OutsideRouteLanesTest`` on a SUMO network. Pure.

Reproduces ``_is_outside_driving_lanes`` and ``_is_at_wrong_lane`` of scenario_runner's
``srunner/scenariomanager/scenarioatomics/atomic_criteria.py`` (branch ``leaderboard-1.0``)
with SUMO's lanes for CARLA's map queries:

* CARLA's ``map.get_waypoint(location, project_to_road=True, lane_type=Driving)`` is the
  nearest point of any lane a passenger car may use (normal or junction-internal), found by
  :class:`DrivingLanes`;
* *off the lanes*: the ego centre is more than lane width / 2 + 1.3 m from that point
  (CARLA's ``ALLOWED_OUT_DISTANCE``); CARLA also accepts a nearer parking lane, which SUMO
  networks imported from CARLA's towns do not hold;
* *wrong lane* (:class:`WrongLaneJudge`): never inside a junction; on entering another lane,
  right after a junction the ego's heading is compared with the lane's (120 degrees or more
  apart: wrong), elsewhere a jump of the lane direction between 150 and 210 degrees (crossing
  the centre line) flips the state, and any other change clears it.

Leaderboard 2.0's test (``lb2``; scenario_runner's 2.0 ``atomic_criteria.py``) differs in
two rules, kept beside: lanes are left beyond width / 2 + 0.5 m, and away from junctions only
a jump strictly between 150 and 210 degrees flips the state, which nothing else clears.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from icrsumo.world.networks import RoadNet

#: OutsideRouteLanesTest.ALLOWED_OUT_DISTANCE (m), Leaderboard 1.0 and 2.0
ALLOWED_OUT_DISTANCE = 1.3
ALLOWED_OUT_DISTANCE_LB2 = 0.5
#: OutsideRouteLanesTest.MAX_ALLOWED_VEHICLE_ANGLE (degrees)
MAX_ALLOWED_VEHICLE_ANGLE = 120.0
#: OutsideRouteLanesTest.MAX_ALLOWED_WAYPOINT_ANGLE (degrees)
MAX_ALLOWED_WAYPOINT_ANGLE = 150.0
#: side (m) of the grid cells that index lane segments
CELL_M = 10.0


@dataclass(frozen=True)
class LanePoint:
    """The nearest point of a driving lane: ``lane`` id, ``dist`` (m) from the query point,
    lane ``heading`` there (rad, counter-clockwise from +x), lane ``width`` (m), whether the
    lane lies inside a junction, and its ``speed_limit`` (m/s)."""

    lane: str
    dist: float
    heading: float
    width: float
    junction: bool
    speed_limit: float = 0.0


class DrivingLanes:
    """Nearest-driving-lane queries on one network: every passenger lane's centre-line
    segments, indexed in a grid of :data:`CELL_M` cells (a cell lists every segment within
    :data:`CELL_M` of it, so a nearest segment within that distance is always found there;
    farther ones are searched over the whole network)."""

    def __init__(self, net: RoadNet) -> None:
        sn = net.sumolib_net
        ids = sorted(lid for lid, shape in net.lane_shape.items() if len(shape) >= 2)
        a, b, lane_idx = [], [], []
        for i, lid in enumerate(ids):
            shape = net.lane_shape[lid]
            a.append(shape[:-1])
            b.append(shape[1:])
            lane_idx.append(np.full(len(shape) - 1, i))
        self.ids = ids
        self.width = [float(sn.getLane(lid).getWidth()) for lid in ids]
        self.speed = [float(sn.getLane(lid).getSpeed()) for lid in ids]
        self.a = np.concatenate(a)
        self.ab = np.concatenate(b) - self.a
        self.den = np.maximum((self.ab ** 2).sum(axis=1), 1e-12)
        self.lane = np.concatenate(lane_idx)
        self.heading = np.arctan2(self.ab[:, 1], self.ab[:, 0])
        lo = np.minimum(self.a, self.a + self.ab) - CELL_M
        hi = np.maximum(self.a, self.a + self.ab) + CELL_M
        cells: dict[tuple[int, int], list[int]] = {}
        for s, (l0, l1, h0, h1) in enumerate(zip(np.floor(lo[:, 0] / CELL_M).astype(int),
                                                 np.floor(lo[:, 1] / CELL_M).astype(int),
                                                 np.floor(hi[:, 0] / CELL_M).astype(int),
                                                 np.floor(hi[:, 1] / CELL_M).astype(int))):
            for cx in range(l0, h0 + 1):
                for cy in range(l1, h1 + 1):
                    cells.setdefault((cx, cy), []).append(s)
        self._cells = {k: np.asarray(v) for k, v in cells.items()}
        self._all = np.arange(len(self.a))

    def _best(self, x: float, y: float, segs: np.ndarray) -> tuple[int, float]:
        a, ab = self.a[segs], self.ab[segs]
        t = ((x - a[:, 0]) * ab[:, 0] + (y - a[:, 1]) * ab[:, 1]) / self.den[segs]
        np.clip(t, 0.0, 1.0, out=t)
        d = np.hypot(a[:, 0] + ab[:, 0] * t - x, a[:, 1] + ab[:, 1] * t - y)
        k = int(d.argmin())
        return int(segs[k]), float(d[k])

    def nearest(self, x: float, y: float) -> LanePoint:
        """The nearest point of any driving lane to (x, y) m (ties: the first segment in lane-id
        order)."""
        key = (math.floor(x / CELL_M), math.floor(y / CELL_M))
        segs = self._cells.get(key)
        s, d = self._best(x, y, segs) if segs is not None else (-1, math.inf)
        if d > CELL_M:
            s, d = self._best(x, y, self._all)
        li = int(self.lane[s])
        lane = self.ids[li]
        return LanePoint(lane, d, float(self.heading[s]), self.width[li], lane.startswith(":"),
                         self.speed[li])

    @staticmethod
    def off_lanes(p: LanePoint, allowed: float = ALLOWED_OUT_DISTANCE) -> bool:
        """``_is_outside_driving_lanes``: farther than width / 2 + ``allowed`` m (1.3 m: 1.0's,
        0.5 m: 2.0's) from the nearest lane."""
        return p.dist > p.width / 2.0 + allowed


@dataclass(frozen=True)
class WrongLaneState:
    """``_is_at_wrong_lane``'s memory: the lane of the previous step (None before the first),
    the previous nearest lane point, and whether the ego is in a lane of the opposite direction."""

    last_lane: str | None = None
    pre: LanePoint | None = None
    wrong: bool = False


def _deg(rad: float) -> float:
    return math.degrees(rad) % 360.0


def wrong_lane_step(state: WrongLaneState, p: LanePoint, yaw: float, lb2: bool = False) -> WrongLaneState:
    """The wrong-lane state after a step at lane point ``p`` with the ego heading ``yaw`` (rad),
    by Leaderboard 1.0's rule (2.0's with ``lb2``). Before the first step the previous point is
    ``p`` itself (CARLA takes it at the start)."""
    pre = state.pre if state.pre is not None else p
    wrong = state.wrong
    if p.junction:
        wrong = False
    elif state.last_lane != p.lane:
        if pre.junction:  # right after a junction: the ego's heading against the lane's
            angle = (_deg(p.heading) - _deg(yaw)) % 360.0
            wrong = not (angle < MAX_ALLOWED_VEHICLE_ANGLE or angle > 360.0 - MAX_ALLOWED_VEHICLE_ANGLE)
        else:  # a big jump of the lane direction: crossing into (or back from) the other side
            angle = (_deg(pre.heading) - _deg(p.heading)) % 360.0
            if lb2:
                if MAX_ALLOWED_WAYPOINT_ANGLE < angle < 360.0 - MAX_ALLOWED_WAYPOINT_ANGLE:
                    wrong = not wrong
            elif MAX_ALLOWED_WAYPOINT_ANGLE <= angle <= 360.0 - MAX_ALLOWED_WAYPOINT_ANGLE:
                wrong = not wrong
            else:
                wrong = False
    return WrongLaneState(p.lane, p, wrong)


@lru_cache(maxsize=16)
def driving_lanes(net: RoadNet) -> DrivingLanes:
    """The :class:`DrivingLanes` of ``net`` (built once per network and process)."""
    return DrivingLanes(net)
