"""A Gymnasium environment over one scenario and one instruction sequence: ``icrsumo/ICRDrive-v0``.

``import icrsumo.app.env`` registers the id (or pass ``"icrsumo.app.env:icrsumo/ICRDrive-v0"`` to
``gymnasium.make``, which imports the module itself). One ``step`` is one agent decision
(0.1 s: the loop's 2 SUMO steps of 0.05 s), the same closed loop as ``icrsumo evaluate``
(:class:`icrsumo.sim.Episode`): with the same actions, the same episode log.

Observation (``Dict``): ``bev`` (7, 128, 128) uint8 raster (channels of
``icrsumo.render.CHANNELS``, heading up); ``speed`` (1,) float32 m/s; ``instruction`` and
``notice`` texts (``gymnasium.spaces.Text`` over printable ASCII plus every character of the
route's instruction file, at most ``max_text_length`` characters, "" when none is active; or,
with ``text_space="bytes"``, (max_text_length,) uint8 UTF-8 bytes padded with zeros, for
libraries without Text support). Every ``info`` also carries ``t`` (s), ``instruction_id`` and
``compass`` (the ego's heading, rad, counter-clockwise from the map's x axis: the IMU compass
that the learned agents' instruction memory reads).

Action: ``action_type="control"`` (default): Box [steer, throttle, brake] in [-1, 1] x [0, 1]
x [0, 1]; ``"waypoints"``: Box (n_waypoints, 2) m in the ego frame (x forward, y left, 0.5 s
apart; the speed is their spacing), tracked by the built-in controller. Actions outside the
box are clipped to it; NaN raises :class:`icrsumo.agents.base.AgentError`. With ``asking=True``
the action is a ``Dict``: that box under the action type's name (``"control"`` or
``"waypoints"``) and ``"ask"``, ``Discrete(2)``: 1 asks the navigator for clarification (it
answers with the route's next maneuver in the baseline's words, 2 simulated seconds later, at
most once per maneuver; :mod:`icrsumo.sim.asking`). The answer is then the observation's
``instruction`` until the next instruction is triggered, and ``info["answer"]`` is True while it
is; ``info["asks"]`` counts the asks so far (the episode log keeps them).

Reward per step, in route-completion points (the Driving Score's units, 0-100)::

    r = (RC_t - RC_{t-1})                                   progress: sums to the episode's RC
        - sum over new penalised infractions of 100 (1 - f)  f: Leaderboard factor (pedestrian 0.50,
                                                             vehicle 0.60, static 0.65, red light
                                                             0.70, stop sign 0.80), counted as in
                                                             scoring
        - 100 * d_outside / L                                d_outside: route advance (m) made this
                                                             step off the driving lanes or against
                                                             the traffic; L: route length (m)

``terminated`` when the episode ends as completed or route deviation (termination classes
done / RD); ``truncated`` when it ends in a TO class (route timeout, agent blocked, stuck,
simulator error). At the end ``info`` holds the Leaderboard metrics (``DS``, ``RC``, ``IS``,
``infractions``, ``termination``, ``termination_class``, ``outside_lanes_pct``) as
``icrsumo.scoring.score_episode`` gives them for the episode's log.

``reset(seed=...)`` seeds ``np_random`` (action-space sampling); the simulation itself is
fixed by the scenario (its SUMO seed and traffic), so every reset starts the same episode and
the same actions give the same observations. ``reset(options={"family": "misleading", "k":
3})`` picks another instruction sequence of the route for that episode.

libsumo runs one simulation per process: resetting a second environment in the same process
closes the first one's simulation (stepping it then raises). For parallel environments use
``gymnasium.vector.AsyncVectorEnv`` (one process each).
"""

from __future__ import annotations

import string
import weakref
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from icrsumo.agents.base import Action, AgentError, Observation
from icrsumo.core.errors import InputError
from icrsumo.core.types import InstructionSet
from icrsumo.core.vocab import EventKind, TerminationClass
from icrsumo.evaluation.bundled import DEFAULT_ROUTE, DEFAULT_SUITE, bundled_route
from icrsumo.instructions.store import read_instruction_sets
from icrsumo.render import to_rgb
from icrsumo.scoring import score_episode
from icrsumo.scoring.lb1 import CollisionCounter
from icrsumo.scoring.penalties import PENALTIES
from icrsumo.sim.callbacks import EpisodeCallback, StepRecord
from icrsumo.sim.episode import Episode, RunOptions
from icrsumo.world.dynamics import Control, VehicleParams
from icrsumo.world.scenario import Scenario, read_scenario

ENV_ID = "icrsumo/ICRDrive-v0"


def to_observation(obs: dict[str, Any], info: dict[str, Any]) -> Observation:
    """The agent protocol's :class:`Observation` of an environment observation and the
    ``info`` that came with it (``t``, ``instruction_id``, ``compass``): what ``agent.act`` takes, so any
    icrsumo agent drives the environment (``agent.reset(info["episode_info"])`` after
    ``env.reset()``; ``env.agent_action(agent.act(...))`` as the step's action)."""
    def text(v: Any) -> str:
        if isinstance(v, np.ndarray):
            return bytes(v).rstrip(b"\0").decode("utf-8", "replace")
        return str(v)

    return Observation(t=float(info["t"]), bev=np.asarray(obs["bev"]),
                       speed=float(np.asarray(obs["speed"])[0]), instruction=text(obs["instruction"]),
                       instruction_id=int(info["instruction_id"]), notice=text(obs["notice"]),
                       answer=bool(info.get("answer", False)), compass=float(info.get("compass", 0.0)))


#: the keys ``reset(options=...)`` reads
RESET_OPTIONS = ("family", "k")


def _reset_options(options: object) -> dict[str, Any]:
    """``reset``'s options checked: None or a dict of :data:`RESET_OPTIONS` keys (a misspelt key
    is an InputError, never a silent baseline)."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise InputError("options", type(options).__name__, "must be a dict (or None)",
                         "give e.g. options={'family': 'misleading', 'k': 0}")
    unknown = [k for k in options if k not in RESET_OPTIONS]
    if unknown:
        import difflib

        near = difflib.get_close_matches(str(unknown[0]), RESET_OPTIONS, n=1)
        hint = f"did you mean {near[0]!r}? " if near else ""
        raise InputError("options", repr(unknown[0]), "unknown reset option",
                         f"{hint}use {', '.join(RESET_OPTIONS)}")
    return options


class _Penalties(EpisodeCallback):
    """The penalised event infractions of an episode as they happen (``kinds``, in order): the
    collisions :class:`~icrsumo.scoring.lb1.CollisionCounter` counts (on the positions the log
    stores), every red light and stop sign."""

    def __init__(self) -> None:
        self.counter = CollisionCounter()
        self.kinds: list[EventKind] = []

    def on_step(self, episode: Episode, step: StepRecord) -> None:
        x, y = round(step.x, 2) + 0.0, round(step.y, 2) + 0.0
        self.kinds += [EventKind(e.kind) for e in self.counter.step(step.t, x, y, step.events)]
        self.kinds += [EventKind(e.kind) for e in step.events
                       if e.kind in (EventKind.RED_LIGHT, EventKind.STOP_SIGN)]
ACTION_TYPES = ("control", "waypoints")
TEXT_SPACES = ("text", "bytes")
#: bound of the waypoint action box (m, ego frame)
WAYPOINT_LIMIT_M = 64.0
#: the name episode logs of the environment are stored under
LOG_AGENT = "gymnasium"

_live: weakref.ref | None = None  # the environment whose simulation is running in this process


class ICRDriveEnv(gym.Env):
    """The closed loop of one scenario and instruction sequence as a ``gymnasium.Env`` (see the
    module docstring for spaces, reward and termination).

    ``scenario`` / ``instructions``: a scenario folder (``convert-routes``) and its route's
    instruction file (``generate``), or Scenario / InstructionSet objects; when both are None,
    the bundled ``route`` of ``suite`` (default tiny_003, 78 m, one left turn) converted and
    generated into the cache on first use (:func:`icrsumo.evaluation.bundled.bundled_route`).
    ``family`` / ``k``: which sequence of the route (default the baseline). ``asking``: the
    action may ask the navigator for clarification (module docstring); it needs the route's
    baseline sequence among ``instructions``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, scenario: str | Path | Scenario | None = None,
                 instructions: str | Path | InstructionSet | list[InstructionSet] | None = None, *,
                 route: str = DEFAULT_ROUTE, suite: str = DEFAULT_SUITE, traffic: str = "normal",
                 family: str = "baseline", k: int = 0, action_type: str = "control",
                 n_waypoints: int = 4, text_space: str = "text", max_text_length: int = 256,
                 render_mode: str | None = None, asking: bool = False) -> None:
        if action_type not in ACTION_TYPES:
            raise InputError("action_type", action_type, "unknown action type", "use control or waypoints")
        if text_space not in TEXT_SPACES:
            raise InputError("text_space", text_space, "unknown text space", "use text or bytes")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise InputError("render_mode", str(render_mode), "unsupported", "use rgb_array or None")
        if not 1 <= n_waypoints <= 32:
            raise InputError("n_waypoints", str(n_waypoints), "out of range", "use 1 to 32")
        if scenario is None and instructions is None:
            sc_dir, instr_path = bundled_route(route, suite, traffic)
            scenario, instructions = sc_dir, instr_path
        elif scenario is None or instructions is None:
            raise InputError("ICRDriveEnv", "scenario/instructions", "give both or neither",
                             "pass a scenario folder and its route's instruction file")
        self.scenario = scenario if isinstance(scenario, Scenario) else read_scenario(Path(scenario))
        if isinstance(instructions, InstructionSet):
            sets = [instructions]
        elif isinstance(instructions, (list, tuple)):
            sets = list(instructions)
        else:
            sets = read_instruction_sets(Path(instructions))
        self.sets = {(s.family, s.k): s for s in sets}
        self.family, self.k = family, k
        self._set(family, k)  # fail early on an unknown sequence
        if not isinstance(asking, bool):
            raise InputError("asking", repr(asking)[:40], "must be True or False", "give a bool")
        self.asking = asking
        if asking and ("baseline", 0) not in self.sets:
            raise InputError("asking", self.scenario.route_id,
                             "needs the route's baseline instruction sequence, whose words answer the agent",
                             "pass the route's instruction file (or its baseline sequence among the sets)")
        self.action_type, self.n_waypoints = action_type, n_waypoints
        self.text_space, self.max_text_length = text_space, max_text_length
        self.render_mode = render_mode
        self.opts = RunOptions(asking=asking)
        bev = self.opts.bev
        chars = set(string.digits + string.ascii_letters + string.punctuation + " ")
        for s in sets:
            for ins in s.instructions:
                chars.update(ins.rendered())
            for n in s.notices:
                chars.update(n.text)
        chars -= set("\n\r\t\x0b\x0c")
        if text_space == "text":
            text = spaces.Text(max_text_length, min_length=0, charset=frozenset(chars))
        else:
            text = spaces.Box(0, 255, (max_text_length,), np.uint8)
        self.observation_space = spaces.Dict({
            "bev": spaces.Box(0, 255, (len(bev.channels), bev.height, bev.width), np.uint8),
            "speed": spaces.Box(0.0, VehicleParams().max_speed, (1,), np.float32),
            "instruction": text,
            "notice": text,
        })
        if action_type == "control":
            self.drive_space = spaces.Box(np.array([-1.0, 0.0, 0.0], np.float32),
                                          np.array([1.0, 1.0, 1.0], np.float32), dtype=np.float32)
        else:
            self.drive_space = spaces.Box(-WAYPOINT_LIMIT_M, WAYPOINT_LIMIT_M, (n_waypoints, 2), np.float32)
        #: the action space: the drive box, or with asking a Dict of it and ``ask``
        self.action_space = spaces.Dict({action_type: self.drive_space, "ask": spaces.Discrete(2)}) \
            if asking else self.drive_space
        self._episode: Episode | None = None
        self._obs: Observation | None = None
        self._suspended = False

    # ------------------------------------------------------------------ helpers
    def _set(self, family: str, k: int) -> InstructionSet:
        if not isinstance(family, str):
            raise InputError("options", "family", f"must be a family name, not {type(family).__name__}",
                             "give e.g. options={'family': 'misleading', 'k': 0}")
        if isinstance(k, bool) or not isinstance(k, int):
            raise InputError("options", "k", f"must be an integer, not {k!r}"[:80],
                             "give e.g. options={'k': 0}")
        key = (family, 0 if family == "baseline" else int(k))
        if key not in self.sets:
            have = ", ".join(f"{f}:{kk}" for f, kk in list(self.sets)[:6])
            raise InputError("family/k", f"{family} k={k}", "no such instruction sequence for this route",
                             f"pick one of {have}, ...")
        return self.sets[key]

    def _text(self, text: str) -> str | np.ndarray:
        if self.text_space == "text":
            return text[: self.max_text_length]
        out = np.zeros(self.max_text_length, np.uint8)
        raw = text.encode("utf-8")[: self.max_text_length]
        out[: len(raw)] = np.frombuffer(raw, np.uint8)
        return out

    def _observe(self, obs: Observation) -> dict[str, Any]:
        return {"bev": obs.bev.copy(), "speed": np.array([obs.speed], np.float32),
                "instruction": self._text(obs.instruction), "notice": self._text(obs.notice)}

    def _action(self, action: Any) -> Action:
        ask = False
        if self.asking:
            if not isinstance(action, dict) or set(action) != {self.action_type, "ask"}:
                raise AgentError(f"with asking the action is a dict with keys {self.action_type!r} and "
                                 f"'ask', got {type(action).__name__}")
            flag = np.asarray(action["ask"])
            if flag.shape != () or flag.item() not in (0, 1):
                raise AgentError(f"action['ask'] must be 0 or 1, got {action['ask']!r}"[:120])
            action, ask = action[self.action_type], bool(flag.item())
        space = self.drive_space
        a = np.asarray(action, dtype=np.float64)
        if a.shape != space.shape:
            raise AgentError(f"action must have shape {space.shape}, got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise AgentError("action contains NaN or inf")
        a = np.clip(a, space.low, space.high)
        if self.action_type == "control":
            control = Control(steer=float(a[0]), throttle=float(a[1]), brake=float(a[2]))
            return Action(control=control, ask=ask)
        return Action(waypoints=a, ask=ask)

    def _rc(self) -> float:
        mon = self._episode.monitor
        return mon.completion_pct if mon is not None else 0.0

    def _close_episode(self) -> None:
        global _live
        if self._episode is not None:
            self._episode.close()
            self._episode = None
        if _live is not None and _live() is self:
            _live = None

    def _suspend(self) -> None:
        """Another environment of this process needs libsumo: close this one's simulation."""
        self._close_episode()
        self._suspended = True

    # ------------------------------------------------------------------ gymnasium API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start the episode (SUMO, warm-up, ego insertion); (observation, info)."""
        global _live
        super().reset(seed=seed)
        options = _reset_options(options)
        iset = self._set(options.get("family", self.family), options.get("k", self.k))
        self._close_episode()
        other = _live() if _live is not None else None
        if other is not None and other is not self:
            other._suspend()
        self._suspended = False
        self._penalties = _Penalties()
        self._episode = Episode(self.scenario, iset, self.opts, callbacks=(self._penalties,),
                                baseline=self.sets.get(("baseline", 0)))
        _live = weakref.ref(self)
        obs = self._episode.start()
        if obs is None:  # ended before the first decision: the simulator failed
            raise RuntimeError(f"the simulation of {self.scenario.route_id} failed at its start: "
                               f"{self._episode.message or self._episode.termination}")
        self._obs = obs
        self._rc_prev, self._n_inf, self._out_prev = self._rc(), 0, 0.0
        info = {"route_id": self.scenario.route_id, "town": self.scenario.town, "family": iset.family,
                "k": iset.k, "route_length": self._episode.route.length,
                "control_dt": self._episode.info.control_dt, "t": obs.t, "instruction_id": obs.instruction_id,
                "compass": obs.compass, "net": str(self.scenario.net), "episode_info": self._episode.info,
                **self._asking_info(obs)}
        return self._observe(obs), info

    def step(self, action: Any):
        """One decision: hold ``action`` for 0.1 s; (observation, reward, terminated, truncated, info)."""
        ep = self._episode
        if ep is None:
            if self._suspended:
                raise RuntimeError("this ICRDrive environment's simulation was closed because another one "
                                   "in the same process was reset (libsumo runs one simulation per "
                                   "process); use gymnasium.vector.AsyncVectorEnv for several environments")
            raise RuntimeError("call reset() before step()")
        if ep.done:
            raise RuntimeError("the episode has ended; call reset()")
        obs = ep.step(self._action(action))
        # reward: route-completion points gained, minus infractions and driving outside the lanes
        rc = self._rc()
        reward = rc - self._rc_prev
        self._rc_prev = rc
        infractions = self._penalties.kinds
        for kind in infractions[self._n_inf:]:
            reward -= 100.0 * (1.0 - PENALTIES[kind])
        self._n_inf = len(infractions)
        out_m = ep.monitor.outside_m
        if ep.route.length > 0:
            reward -= 100.0 * (out_m - self._out_prev) / ep.route.length
        self._out_prev = out_m
        seen = obs if obs is not None else self._obs  # at the end, the last observation stands
        info: dict[str, Any] = {"t": seen.t, "progress": ep.progress, "route_length": ep.route.length,
                                "instruction_id": seen.instruction_id, "compass": seen.compass,
                                "infractions_so_far": len(infractions), **self._asking_info(seen)}
        terminated = truncated = False
        if obs is None:
            obs = self._obs  # the episode ended: the last observation stands
            result = score_episode(ep.log(LOG_AGENT))
            cls = result.termination_class
            terminated, truncated = cls != TerminationClass.TO, cls == TerminationClass.TO
            info.update({
                "DS": result.ds, "RC": result.rc, "IS": result.is_, "termination": result.termination,
                "termination_class": cls.value, "outside_lanes_pct": result.outside_lanes_pct,
                "infractions": [{"kind": i.kind, "factor": i.factor, "t": i.t} for i in result.infractions],
                "duration": result.duration, "message": ep.message,
            })
        self._obs = obs
        return self._observe(obs), float(reward), bool(terminated), bool(truncated), info

    def _asking_info(self, obs: Observation) -> dict[str, Any]:
        """``answer`` and ``asks`` of ``info`` (with asking only)."""
        nav = self._episode.navigator if self._episode is not None else None
        return {"answer": obs.answer, "asks": len(nav.asks)} if nav is not None else {}

    def agent_action(self, action: Action) -> np.ndarray | dict[str, Any]:
        """An agent's :class:`Action` as this environment's action: [steer, throttle, brake]
        (``action_type="control"``) or the first ``n_waypoints`` waypoints, the last one
        repeated where there are fewer (``"waypoints"``; the speed is their spacing, so a
        ``target_speed`` is not used); with asking, a dict of it and ``ask`` (0 or 1). An
        AgentError when the agent's kind of action does not fit the environment's."""
        drive = self._drive(action)
        return {self.action_type: drive, "ask": int(action.ask)} if self.asking else drive

    def _drive(self, action: Action) -> np.ndarray:
        """The drive part of :meth:`agent_action`."""
        if self.action_type == "control":
            if action.control is None:
                raise AgentError("this environment takes control actions and the agent gave waypoints: make "
                                 "it with action_type='waypoints'")
            c = action.control
            return np.array([c.steer, c.throttle, c.brake], np.float32)
        if action.waypoints is None:
            raise AgentError("this environment takes waypoints and the agent gave controls: make it with "
                             "action_type='control'")
        wp = np.asarray(action.waypoints, np.float32).reshape(-1, 2)
        if len(wp) == 0:
            raise AgentError("the agent gave no waypoints")
        idx = np.minimum(np.arange(self.n_waypoints), len(wp) - 1)
        return wp[idx]

    def render(self) -> np.ndarray | None:
        """``rgb_array``: the current BEV raster as an (128, 128, 3) RGB image."""
        if self.render_mode != "rgb_array" or self._obs is None:
            return None
        return to_rgb(self._obs.bev)

    def close(self) -> None:
        """End the simulation (idempotent)."""
        self._close_episode()
        super().close()

    def episode_log(self):
        """The :class:`icrsumo.core.types.EpisodeLog` of the current episode so far."""
        if self._episode is None:
            raise RuntimeError("no episode: call reset()")
        return self._episode.log(LOG_AGENT)


if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point="icrsumo.app.env:ICRDriveEnv")
