"""Frozen records shared across icrsumo. Units: metres, seconds, radians unless stated."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Waypoint:
    """One leaderboard waypoint as written in the route file (file coordinates).

    ``yaw`` is in degrees as in the file, ``None`` when the file gives none.
    """

    x: float
    y: float
    z: float = 0.0
    pitch: float = 0.0
    roll: float = 0.0
    yaw: float | None = None


@dataclass(frozen=True)
class RouteSpec:
    """One ``<route>`` of a leaderboard route file.

    ``index`` is its 0-based position in the file; ``weather`` keeps the attributes of the
    first ``<weather>`` element verbatim, in file order.
    """

    id: str
    town: str
    waypoints: tuple[Waypoint, ...]
    weather: tuple[tuple[str, str], ...] = ()
    index: int = 0


@dataclass(frozen=True)
class LanePos:
    """A position on a SUMO lane: lane id, distance from the lane start (m), and the
    world pose there (x, y in m, heading in rad, counter-clockwise from +x)."""

    lane: str
    pos: float
    x: float
    y: float
    heading: float

    @property
    def edge(self) -> str:
        return self.lane.rsplit("_", 1)[0]

    @property
    def lane_index(self) -> int:
        return int(self.lane.rsplit("_", 1)[1])


@dataclass(frozen=True)
class JunctionPass:
    """The ego route crossing one junction from edge ``from_edge`` to ``to_edge``.

    ``direction`` is SUMO's connection direction (s, l, r, t, L, R: straight, left, right,
    turn-around, partly left, partly right); ``choice`` is True when ``from_edge`` offers more
    than one onward edge (a real maneuver). ``pos`` is the route position (m) of the junction
    entry. ``from_lane``/``to_lane`` are the lane indices of the connection used.
    """

    junction: str
    junction_type: str
    from_edge: str
    to_edge: str
    from_lane: int
    to_lane: int
    via: str
    direction: str
    choice: bool
    roundabout: bool
    pos: float


@dataclass(frozen=True)
class LaneChange:
    """A lane change the route requires on ``edge`` (lane indices: 0 is the rightmost)."""

    edge: str
    pos: float
    from_lane: int
    to_lane: int

    @property
    def direction(self) -> str:
        return "left" if self.to_lane > self.from_lane else "right"


@dataclass(frozen=True)
class EgoRoute:
    """The ego's planned route through a network.

    ``edges``: normal edge ids in driving order; ``lanes[i]``: indices of the lanes of
    ``edges[i]`` from which the route can continue; ``lane_path[i]``: the lane driven on
    ``edges[i]``; ``polyline``: (N, 2) centre line in m from start to end; ``length`` in m.
    """

    edges: tuple[str, ...]
    lanes: tuple[tuple[int, ...], ...]
    lane_path: tuple[int, ...]
    start: LanePos
    end: LanePos
    polyline: tuple[tuple[float, float], ...]
    length: float
    junctions: tuple[JunctionPass, ...]
    lane_changes: tuple[LaneChange, ...]
