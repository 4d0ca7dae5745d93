"""The agent protocol: what every agent (built-in, learned, user's, remote) implements.

An agent is reset with an :class:`EpisodeInfo` (never the route) and acts on an
:class:`Observation` every control step (``control_dt`` s, 10 Hz by default), returning an
:class:`Action`: low-level controls, or future waypoints in the ego frame that the built-in
controller tracks. Privileged agents (``privileged = True``: route-oracle,
instruction-follower) also receive a :class:`World` view of the simulator state.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from ..dynamics import Control

if TYPE_CHECKING:
    from ..dynamics import EgoState
    from ..networks import RoadNet
    from ..types import EgoRoute


@dataclass(frozen=True)
class EpisodeInfo:
    """What an agent learns at reset: route id, town, network path (the map is public; the
    route is not), simulation and control step (s), and a seed for stochastic agents."""

    route_id: str
    town: str
    net: str
    step_length: float
    control_dt: float
    seed: int


@dataclass(frozen=True)
class World:
    """Privileged simulator view for built-in privileged agents (never given to others).

    ``vehicles``: (N, 5) other vehicles near the ego: centre x, y (m), yaw (rad), length,
    width (m); ``pedestrians``: (M, 2) centres (m); ``lane``/``lane_pos``: SUMO's lane of the
    ego ("" when off the road) and position on it (m); ``tl_states``: tls id -> state string;
    ``route``: the scenario's route (only the route-oracle may use it).
    """

    net: RoadNet
    ego: EgoState
    lane: str
    lane_pos: float
    vehicles: np.ndarray
    pedestrians: np.ndarray
    tl_states: dict[str, str]
    route: EgoRoute | None
    progress: float


@dataclass(frozen=True)
class Observation:
    """What an agent sees at time ``t`` (s): ``bev`` (C, H, W) uint8 raster (channels in
    ``icrsumo.render.CHANNELS``, heading up), ``speed`` (m/s), the active ``instruction``
    text with placeholders filled (and its id, -1 before the first), and the active
    ``notice`` ("" if none). ``world`` is set only for privileged agents."""

    t: float
    bev: np.ndarray
    speed: float
    instruction: str
    instruction_id: int
    notice: str
    world: World | None = None


@dataclass(frozen=True)
class Action:
    """An agent's output: ``control`` (low-level), or ``waypoints`` ((N, 2) m, ego frame, x
    forward, y left, 0.5 s apart) with an optional ``target_speed`` (m/s) for the controller."""

    control: Control | None = None
    waypoints: np.ndarray | None = None
    target_speed: float | None = None


@runtime_checkable
class Agent(Protocol):
    """The agent protocol. ``name`` identifies it in results; ``privileged`` is False for
    every agent that must drive from the BEV raster and the instruction alone."""

    name: str
    privileged: bool

    def reset(self, info: EpisodeInfo) -> None: ...

    def act(self, obs: Observation) -> Action: ...


class AgentError(RuntimeError):
    """An agent broke the protocol (wrong action type or shape, NaN, ...)."""


def validate_action(action: object) -> Action:
    """Check an agent's output; raise :class:`AgentError` saying what is wrong in plain words."""
    if not isinstance(action, Action):
        raise AgentError(f"act() returned {type(action).__name__}, expected icrsumo.agents.base.Action")
    if action.control is None and action.waypoints is None:
        raise AgentError("act() returned an Action with neither control nor waypoints")
    if action.control is not None:
        c = action.control
        values = (c.steer, c.throttle, c.brake)
        if not all(isinstance(v, (int, float, np.floating, np.integer)) and np.isfinite(v) for v in values):
            raise AgentError(f"control values must be finite numbers, got steer={c.steer!r}, "
                             f"throttle={c.throttle!r}, brake={c.brake!r}")
        return action
    wps = np.asarray(action.waypoints)
    if wps.ndim != 2 or wps.shape[1] != 2 or wps.shape[0] < 1:
        raise AgentError(f"waypoints must have shape (N, 2) with N >= 1, got {wps.shape}")
    if not np.issubdtype(wps.dtype, np.number) or not np.all(np.isfinite(wps)):
        raise AgentError("waypoints contain NaN, inf or non-numbers")
    ts = action.target_speed
    if ts is not None and not (isinstance(ts, (int, float, np.floating, np.integer)) and np.isfinite(ts)):
        raise AgentError(f"target_speed must be a finite number or None, got {ts!r}")
    return action
