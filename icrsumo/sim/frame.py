"""What the simulator reports after one step, as frozen records (no libsumo here).

:class:`SimFrame` is everything the sensors (:mod:`icrsumo.sim.sensors`) and the observation
need from SUMO at one simulation step; the backend (:mod:`icrsumo.sim.backend`) is the only
code that fills it, so sensors and the loop can be unit-tested from recorded frames.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

#: the empty, read-only light-state mapping (a frame's default)
NO_LIGHTS: Mapping[str, str] = MappingProxyType({})


@dataclass(frozen=True)
class Contact:
    """A collision SUMO reports between the ego and ``other`` this step (a vehicle id, or a
    person id when ``pedestrian``)."""

    other: str
    pedestrian: bool


@dataclass(frozen=True)
class SimFrame:
    """SUMO's state at simulation time ``t`` (s), right after a step.

    ``ego_present``: the ego is still in the simulation (False once SUMO teleported or removed
    it; the other fields are then empty). ``lane``: SUMO's lane of the ego ("" while it is
    off every lane), ``lane_pos``: its position on that lane (m). ``contacts``: the ego's
    collisions this step; ``any_collision``: SUMO reported a collision this step, the ego's or
    others' (the sensors refresh their contacts then). ``teleports``: background vehicles that
    started a teleport this step (a jam). ``tl_states``: traffic-light id -> signal state
    string (one character per link index): every light of the network on frames read with the
    surroundings, else the lights the reader asked for. ``vehicles``
    (N, 5): other vehicles within the context radius, centre x, y (m), yaw (rad), length,
    width (m); ``pedestrians`` (M, 2): person centres (m); both are None on frames read
    without the surroundings. ``traffic_speed``: the mean speed (m/s) of every other vehicle in
    the simulation (Leaderboard 2.0's MinimumSpeedRouteTest compares the ego with it), -1 when
    there is none.
    """

    t: float
    ego_present: bool
    lane: str = ""
    lane_pos: float = 0.0
    contacts: tuple[Contact, ...] = ()
    any_collision: bool = False
    teleports: tuple[str, ...] = ()
    tl_states: Mapping[str, str] = field(default_factory=lambda: NO_LIGHTS)
    vehicles: np.ndarray | None = None
    pedestrians: np.ndarray | None = None
    traffic_speed: float = -1.0


def frame_to_dict(frame: SimFrame) -> dict:
    """The frame as plain JSON types (floats exact; the surroundings are left out)."""
    return {"t": frame.t, "ego_present": frame.ego_present, "lane": frame.lane, "lane_pos": frame.lane_pos,
            "contacts": [[c.other, c.pedestrian] for c in frame.contacts],
            "any_collision": frame.any_collision, "teleports": list(frame.teleports),
            "tl_states": dict(frame.tl_states), "traffic_speed": frame.traffic_speed}


def frame_from_dict(d: dict) -> SimFrame:
    """Inverse of :func:`frame_to_dict` (without the surroundings)."""
    return SimFrame(t=float(d["t"]), ego_present=bool(d["ego_present"]), lane=str(d["lane"]),
                    lane_pos=float(d["lane_pos"]),
                    contacts=tuple(Contact(str(o), bool(p)) for o, p in d["contacts"]),
                    any_collision=bool(d["any_collision"]), teleports=tuple(d["teleports"]),
                    tl_states=dict(d["tl_states"]), traffic_speed=float(d.get("traffic_speed", -1.0)))
