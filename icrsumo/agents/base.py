"""The agent protocol: what every agent (built-in, learned, user's, remote) implements.

An agent is reset with an :class:`EpisodeInfo` (never the route) and acts on an
:class:`Observation` every control step (``control_dt`` s, 10 Hz by default), returning an
:class:`Action`: low-level controls, or future waypoints in the ego frame that the built-in
controller tracks. Privileged agents (``privileged = True``: route-oracle,
instruction-follower) also receive a :class:`World` view of the simulator state; its route
only when they also declare ``needs_route = True`` (the route-oracle alone).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from icrsumo.world.dynamics import Control

if TYPE_CHECKING:
    from icrsumo.core.types import EgoRoute
    from icrsumo.world.dynamics import EgoState
    from icrsumo.world.networks import RoadNet


@dataclass(frozen=True)
class EpisodeInfo:
    """What an agent learns at reset: route id, town, network path (the map is public; the
    route is not), simulation and control step (s), a seed for stochastic agents, and
    ``asking``: whether the navigator answers the agent's asks in this episode
    (:attr:`Action.ask`; off unless the run turns it on)."""

    route_id: str
    town: str
    net: str
    step_length: float
    control_dt: float
    seed: int
    asking: bool = False


@dataclass(frozen=True)
class World:
    """Privileged simulator view for built-in privileged agents (never given to others).

    ``vehicles``: (N, 5) other vehicles near the ego: centre x, y (m), yaw (rad), length,
    width (m); ``pedestrians``: (M, 2) centres (m); ``lane``/``lane_pos``: SUMO's lane of the
    ego ("" when off the road) and position on it (m); ``tl_states``: tls id -> state string;
    ``route``: the scenario's route, only for agents that declare ``needs_route = True``
    (the route-oracle), else None.
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
    ``notice`` ("" if none). ``world`` is set only for privileged agents. ``answer``: the
    instruction is the navigator's answer to the agent's ask (its id then that of the baseline
    instruction it quotes), shown from its arrival until the next instruction is triggered.
    ``compass``: the ego's heading (rad, counter-clockwise from the map's x axis, in [-pi, pi]),
    the IMU compass of the leaderboard's sensor suite (the loop always sets it; 0 in
    observations built by hand)."""

    t: float
    bev: np.ndarray
    speed: float
    instruction: str
    instruction_id: int
    notice: str
    world: World | None = None
    answer: bool = False
    compass: float = 0.0


@dataclass(frozen=True)
class Action:
    """An agent's output: ``control`` (low-level), or ``waypoints`` ((N, 2) m, ego frame, x
    forward, y left, 0.5 s apart) with an optional ``target_speed`` (m/s) for the controller.
    ``ask``: ask the navigator for clarification (used only when :attr:`EpisodeInfo.asking` is
    on: it answers with the route's next maneuver after a delay, at most once per maneuver,
    and counts every ask; see :mod:`icrsumo.sim.asking`)."""

    control: Control | None = None
    waypoints: np.ndarray | None = None
    target_speed: float | None = None
    ask: bool = False


@runtime_checkable
class Agent(Protocol):
    """The agent protocol. ``name`` identifies it in results; ``privileged`` is False for
    every agent that must drive from the BEV raster and the instruction alone."""

    name: str
    privileged: bool

    def reset(self, info: EpisodeInfo) -> None: ...

    def act(self, obs: Observation) -> Action: ...


def batch_hook(cls: object) -> Callable[[list, list[Observation]], list[Action]] | None:
    """The optional batched-inference hook of an agent class as ``f(agents, observations)``, or
    None. Two forms (``icrsumo serve-agent`` uses it to act for several episodes at once):

    * ``act_batch(agents, observations) -> list[Action]`` as a ``staticmethod`` or
      ``classmethod``: ``agents[i]`` is the episode's own instance (reset for it) and sees
      ``observations[i]``; per-episode state stays in each instance;
    * ``def act_batch(self, observations) -> list[Action]``: called on the first agent of the
      batch, for agents whose ``act`` depends only on the observation and shared weights.

    Either must return what each agent's ``act`` would return for its observation. A factory
    that is not a class but makes instances of one names it as ``agent_class`` (e.g.
    :class:`icrsumo.agents.registry.OnDevice`)."""
    cls = getattr(cls, "agent_class", cls)
    if not isinstance(cls, type):
        return None
    raw = inspect.getattr_static(cls, "act_batch", None)
    if isinstance(raw, (staticmethod, classmethod)):
        fn = cls.act_batch
        return lambda agents, observations: fn(agents, observations)
    if callable(raw):
        return lambda agents, observations: agents[0].act_batch(observations)
    return None


class AgentError(RuntimeError):
    """An agent broke the protocol (wrong action type or shape, NaN, ...)."""


class AgentTimeout(AgentError):
    """An agent did not answer within its time limit (``icrsumo evaluate --agent-timeout``, or a
    remote agent's request timeout). ``icrsumo evaluate`` stores the episode as crashed at once:
    a retry would wait the whole timeout again."""


#: waypoints an action may hold (a controller needs a few metres ahead, not a map)
MAX_WAYPOINTS = 1000


def validate_action(action: object) -> Action:
    """Check an agent's output; raise :class:`AgentError` saying what is wrong in plain words."""
    if not isinstance(action, Action):
        raise AgentError(f"act() returned {type(action).__name__}, expected icrsumo.agents.base.Action")
    if action.control is None and action.waypoints is None:
        raise AgentError("act() returned an Action with neither control nor waypoints")
    if not isinstance(action.ask, (bool, np.bool_)):
        raise AgentError(f"Action.ask must be True or False, got {action.ask!r}"[:160])
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
    if wps.shape[0] > MAX_WAYPOINTS:
        raise AgentError(f"at most {MAX_WAYPOINTS} waypoints, got {wps.shape[0]}")
    if not np.issubdtype(wps.dtype, np.number) or not np.all(np.isfinite(wps)):
        raise AgentError("waypoints contain NaN, inf or non-numbers")
    ts = action.target_speed
    if ts is not None and not (isinstance(ts, (int, float, np.floating, np.integer)) and np.isfinite(ts)):
        raise AgentError(f"target_speed must be a finite number or None, got {ts!r}")
    return action
