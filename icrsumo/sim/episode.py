"""The closed loop: scenario x instruction sequence x agent -> EpisodeLog. One loop for
:func:`run_episode` (``icrsumo evaluate``, ``run-episode``, ``collect``), the Gymnasium
environment and ``icrsumo check-agent``, all through :class:`Episode`.

Per simulation step (``step_length`` s, 0.05 s = 20 Hz as the Leaderboard): the held action
(controls, or ego-frame waypoints through the built-in controller) drives the kinematic
bicycle model; the backend (:mod:`icrsumo.sim.backend`) places the ego in SUMO, steps and
reads a :class:`~icrsumo.sim.frame.SimFrame`; the pure sensors (:mod:`icrsumo.sim.sensors`)
turn it into events and readings; the step is recorded; the run-ending rules
(:mod:`icrsumo.scoring`) decide. Every ``control_every`` steps (default 2: 10 Hz) the
agent gets an observation: BEV raster, speed, active instruction with ``[x]`` filled, notice
(the surroundings are read, and the BEV rendered, only then). Instructions are issued online
from the ego's progress: the active one is the last whose trigger (m) has been passed, the
same triggers for every variant. With asking on (``RunOptions.asking``) an action's ``ask`` goes
to the navigator (:mod:`icrsumo.sim.asking`), whose answer the agent then reads for a while.

Side effects (the log's columns, timings, video) are :mod:`callbacks <icrsumo.sim.callbacks>`.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path

from icrsumo.agents.base import Action, Agent, EpisodeInfo, Observation, World, validate_action
from icrsumo.core.angles import wrap_angle
from icrsumo.core.errors import Field, InputError, Interrupted, describe
from icrsumo.core.types import EgoRoute, EpisodeLog, Event, InstructionSet
from icrsumo.core.vocab import EventKind, Family, Phase, Termination
from icrsumo.guards.base import Guard, guarded_name
from icrsumo.guards.stream import GuardedStream
from icrsumo.instructions.maneuvers import extract_maneuvers
from icrsumo.render import BevRenderer, BevSpec
from icrsumo.scoring import get_scoring
from icrsumo.scoring.criteria import TerminationMonitor
from icrsumo.scoring.route import DenseRoute
from icrsumo.world.dynamics import Control, EgoState, VehicleParams, step
from icrsumo.world.networks import RoadNet, load_net
from icrsumo.world.scenario import Scenario

from .asking import ASK_DELAY, Navigator
from .backend import SimulatorError, SumoBackend
from .callbacks import EpisodeCallback, LogRecorder, PhaseClock, StepRecord
from .control import WaypointController, WaypointPath
from .drivable import drivable_area
from .frame import SimFrame
from .lanes import driving_lanes
from .match import match_grid
from .sensors import Sensors, SensorState

#: SUMO steps per agent decision (0.05 s x 2 = 10 Hz)
CONTROL_EVERY = 2


@dataclass(frozen=True)
class RunOptions:
    """Episode options: agent rate (``control_every`` SUMO steps per agent decision), the
    BEV spec of the agent's raster (it changes what the agent sees, never the scoring), the
    scoring whose route criteria end the episode (:data:`icrsumo.scoring.SCORINGS`) and
    ``asking``: whether the navigator answers the agent's asks (``Action.ask``), ``ask_delay``
    simulated seconds later (:mod:`icrsumo.sim.asking`; off: asks are ignored); ``on_block``:
    what an instruction a guard blocks leaves the agent (:data:`icrsumo.guards.base.BLOCK_POLICIES`:
    ``keep``, what it was shown before; ``navigator``, the plan's instruction in the baseline's
    words; :mod:`icrsumo.guards.stream`)."""

    control_every: int = CONTROL_EVERY
    bev: BevSpec = BevSpec()
    scoring: str = "lb1"
    asking: bool = False
    ask_delay: float = ASK_DELAY
    on_block: str = "keep"


@cache
def _renderer(net_path: str, spec: BevSpec) -> BevRenderer:
    return BevRenderer(load_net(Path(net_path)), spec)


def ego_route(sc: Scenario) -> EgoRoute:
    """The scenario's route (:attr:`~icrsumo.world.scenario.Scenario.route`, its junction passes and
    lane changes included): what the route-oracle is handed."""
    return sc.route


def _active(triggers: list[float], progress: float) -> int:
    return bisect.bisect_right(triggers, progress + 1e-9) - 1


class Episode:
    """One closed-loop episode as a steppable object.

    ``start()`` starts SUMO (warm-up, ego insertion) and returns the first
    :class:`Observation`; ``step(action)`` checks the action (:func:`validate_action`), holds it
    for ``control_every`` simulation steps and returns the next observation, or None once the
    episode has ended (``termination`` says why). ``log(agent)`` is the :class:`EpisodeLog` so
    far. ``close()`` (or leaving the ``with`` block) ends the SUMO session.
    ``privileged``: observations carry the :class:`World` view (built-in agents only);
    ``needs_route``: that view includes the route (the route-oracle only). With
    ``options.asking``, ``baseline`` (the route's baseline sequence; ``instructions`` itself when
    it is the baseline) words the navigator's answers, and with a ``guard`` under
    ``options.on_block`` navigator, the repairs of blocked instructions. ``clock``: a
    :class:`PhaseClock` the loop laps (None: no timing).
    """

    def __init__(self, scenario: Scenario, instructions: InstructionSet,
                 options: RunOptions = RunOptions(), *, privileged: bool = False,  # noqa: B008
                 needs_route: bool = False, callbacks: Sequence[EpisodeCallback] = (),
                 guard: Guard | None = None, baseline: InstructionSet | None = None,
                 clock: PhaseClock | None = None) -> None:
        self.scenario, self.instructions = scenario, instructions
        self.clock = clock
        self.options, self.privileged, self.needs_route = options, privileged, needs_route
        self.net = net = load_net(scenario.net)
        #: the ego's lane search, narrowed where that picks SUMO's lane (icrsumo.sim.match)
        self._search = match_grid(net).radius
        self.params = params = VehicleParams(length=scenario.ego.length, width=scenario.ego.width)
        #: the route polyline as the log stores it (m, rounded to 0.01; with the lane heading at
        #: each vertex, rad rounded to 1e-4, where the scenario has them) and its dense route
        heads = scenario.headings if len(scenario.headings) == len(scenario.polyline) else None
        self.polyline = tuple(
            (round(float(x), 2) + 0.0, round(float(y), 2) + 0.0)
            + ((round(float(heads[i]), 4) + 0.0,) if heads else ())
            for i, (x, y) in enumerate(scenario.polyline))
        self.route = DenseRoute.from_polyline(self.polyline)
        #: the route the route-oracle is handed (World.route)
        self.ego_route = ego_route(scenario)
        self.sensors = Sensors(net, driving_lanes(net), drivable_area(net), (params.length, params.width))
        self.renderer = _renderer(str(scenario.net), options.bev)
        self.dt = scenario.step_length
        self.instr = instructions.instructions
        self.triggers = [i.trigger for i in self.instr]
        self.texts = [i.rendered() for i in self.instr]
        self.notices = instructions.notices
        #: the instruction guard between the stream and the agent (None: every one is shown)
        self.guarded = None if guard is None else GuardedStream(
            guard, scenario, net, self.instr, self.texts, options.on_block,
            _route_baseline(scenario, instructions, baseline, "the navigator block policy needs the route's "
                            "baseline instructions, whose words replace blocked ones").instructions
            if options.on_block == "navigator" else None)
        #: the navigator that answers the agent's asks (None: asking is off)
        self.navigator = _navigator(scenario, net, instructions, baseline, options.ask_delay) \
            if options.asking else None
        self.controller = WaypointController(params)
        #: what the agent is told at reset
        self.info = EpisodeInfo(route_id=scenario.route_id, town=scenario.town, net=str(scenario.net),
                                step_length=self.dt, control_dt=self.dt * options.control_every,
                                seed=scenario.seed, asking=options.asking)
        #: the log's columns and events (always attached, first)
        self.recorder = LogRecorder()
        self.callbacks: tuple[EpisodeCallback, ...] = (self.recorder, *callbacks)
        self.termination: Termination = Termination.SIM_ERROR
        self.term_t = 0.0
        self.message = ""
        self.done = False
        self.backend: SumoBackend | None = None
        self.state: EgoState | None = None
        self.sensor_state = SensorState()
        self.frame: SimFrame | None = None
        self.monitor: TerminationMonitor | None = None
        self.action = Action(control=Control(brake=1.0))
        self._path: WaypointPath | None = None
        self.scoring = get_scoring(options.scoring)
        self.rules = self.scoring.rules
        # a bound on the steps (the monitor ends the episode first)
        self.n_max = self.scoring.max_steps(self.route.length, self.dt)
        self.k_instr = -1
        #: the index of the instruction the agent is shown (k_instr, unless a guard blocked it)
        self.k_shown = -1
        self.i = 0
        #: the ego's lane -> the lights the sensors need in this step's frame
        self._lights = lambda lane: self.sensors.lights_needed(self.sensor_state, lane)

    # ------------------------------------------------------------------ lifecycle
    def __enter__(self) -> Episode:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """End the SUMO session and the callbacks' outputs (idempotent)."""
        if self.backend is None:
            return
        backend, self.backend = self.backend, None
        try:
            for cb in self.callbacks:
                cb.on_close(self)
        finally:
            backend.close()

    @property
    def progress(self) -> float:
        """Route progress (m): the last point of the dense route passed
        (:class:`~icrsumo.scoring.criteria.TerminationMonitor`)."""
        return self.monitor.progress if self.monitor is not None else 0.0

    def _finish(self, termination: Termination, t: float) -> None:
        self.termination, self.term_t, self.done = termination, t, True
        for cb in self.callbacks:
            cb.on_end(self)

    def abort(self, message: str) -> None:
        """End the episode after a failure off the simulator (the agent's or its guard's call
        raised): termination agent_error at the last recorded step's time, ``message`` as the
        log's; the log keeps the steps recorded so far. Nothing happens once it has ended."""
        if self.done:
            return
        self.message = message
        ts = self.recorder.cols["t"]
        self._finish(Termination.AGENT_ERROR, round(ts[-1], 3) + 0.0 if ts else 0.0)

    def _sim_error(self, err: SimulatorError) -> None:
        try:
            t = self.backend.time
        except SimulatorError:  # SUMO is gone: the last time it reported
            t = self.frame.t if self.frame is not None else 0.0
        self.message = err.message
        self.recorder.events.append(Event(EventKind.SIM_ERROR, t, 0.0, self.message))
        self._finish(Termination.SIM_ERROR, t)

    def start(self) -> Observation | None:
        """Start SUMO, warm up, insert the ego; the first observation (None: ended at once)."""
        for cb in self.callbacks:
            cb.on_start(self)
        if self.guarded is not None:
            self.guarded.reset()
        self.backend = backend = SumoBackend(self.scenario, search=self._search)
        backend.start()
        scenario, params = self.scenario, self.params
        try:
            backend.run_until(scenario.ego_depart)
            sx, sy, sh = scenario.start  # front bumper on the start lane
            self.state = EgoState(sx - 0.5 * params.length * math.cos(sh),
                                  sy - 0.5 * params.length * math.sin(sh), sh)
            backend.insert_ego(sx, sy, sh)
            self.monitor = TerminationMonitor(self.route, round(backend.time, 3), self.rules)
            for cb in self.callbacks:
                cb.on_ready(self)
            if self.clock is not None:
                self.clock.lap(Phase.SUMO_START)
            return self._advance()
        except SimulatorError as err:
            self._sim_error(err)
            return None

    def step(self, action: Action) -> Observation | None:
        """Hold ``action`` (checked: AgentError when invalid) until the next decision; its
        observation, or None once the episode has ended."""
        if self.done or self.backend is None:
            raise RuntimeError("the episode has ended (or was never started)")
        self.action = validate_action(action)
        if self.action.ask and self.navigator is not None:
            self.navigator.ask(self.frame.t, self.progress)
        # the waypoints' polyline, prepared once for the steps the action is held
        self._path = None if self.action.control is not None else WaypointPath(self.action.waypoints)
        try:
            self._apply()
            return self._advance()
        except SimulatorError as err:
            self._sim_error(err)
            return None

    # ------------------------------------------------------------------ the loop
    def _apply(self) -> None:
        """The held action for one simulation step: controls, bicycle model, SUMO step."""
        action, params, dt = self.action, self.params, self.dt
        control = action.control if action.control is not None else self.controller.control(
            self._path, self.state.speed, dt, action.target_speed)
        state = self.state = step(self.state, control, dt, params)
        fx, fy = state.front(params.length)
        clock = self.clock
        if clock is not None:
            clock.lap(Phase.CONTROL)
        self.backend.place_ego(fx, fy, state.yaw)
        if clock is not None:
            clock.lap(Phase.SUMO_IO)
        self.backend.step()
        if clock is not None:
            clock.lap(Phase.SUMO_STEP)
        self.i += 1

    def _advance(self) -> Observation | None:
        """Simulation steps until the next decision (its observation) or the end (None)."""
        every = self.options.control_every
        while True:
            if self.i >= self.n_max:
                self._finish(Termination.ROUTE_TIMEOUT, self.backend.time)
                return None
            observe = self.i % every == 0
            if self._record_step(observe):
                return None
            if observe:
                return self._observation()
            self._apply()

    def _record_step(self, observe: bool) -> bool:
        """Read SUMO's frame, detect events, record the step; True when the episode ended."""
        frame = self.frame = self.backend.read(surroundings=observe, lights=self._lights)
        clock = self.clock
        if clock is not None:
            clock.lap(Phase.SUMO_IO)
        state, t = self.state, frame.t
        if not frame.ego_present:  # SUMO teleported or removed the ego
            self.recorder.events.append(Event(EventKind.EGO_TELEPORT, t, self.progress, "", state.x, state.y))
            self._finish(Termination.STUCK, t)
            return True
        # the rules see the values the log stores (rounded as icrsumo.results.logs rounds them)
        mon = self.monitor
        t, x, y, speed = round(t, 3) + 0.0, round(state.x, 2) + 0.0, round(state.y, 2) + 0.0, \
            round(state.speed, 3) + 0.0
        progress = mon.locate(x, y)
        events, ss = self.sensors.detect(self.sensor_state, frame, state, progress)
        self.sensor_state = ss
        k = self.k_instr = _active(self.triggers, progress)
        if self.guarded is not None:
            k = self.guarded.shown(k, t, progress)
        self.k_shown = k
        rec = StepRecord(t, state.x, state.y, state.yaw, state.speed, progress,
                         self.instr[k].id if k >= 0 else -1, ss.outside, mon.route_dist, tuple(events),
                         frame.traffic_speed, ss.speed_limit)
        if clock is not None:
            clock.lap(Phase.OBSERVATION)
        for cb in self.callbacks:
            cb.on_step(self, rec)
        if clock is not None:
            clock.lap(Phase.RECORDING)
        done = mon.update(t, speed, ss.outside, events, round(frame.traffic_speed, 3) + 0.0,
                          round(ss.speed_limit, 2) + 0.0)
        if clock is not None:
            clock.lap(Phase.RULES)
        if done:
            self._finish(Termination(done), t)
            return True
        return False

    def _shown(self) -> tuple[str, int]:
        """(text, instruction id) the agent reads now: the instruction shown (-1: none), or
        what the guard shows instead (:meth:`GuardedStream.observed`)."""
        if self.guarded is not None:
            return self.guarded.observed()
        k = self.k_shown
        return (self.texts[k], self.instr[k].id) if k >= 0 else ("", -1)

    def _observation(self) -> Observation:
        """The agent's observation at the current step (BEV, speed, instruction, notice)."""
        state, params, progress = self.state, self.params, self.progress
        frame = self.frame
        notice = ""
        for n in self.notices:
            if n.trigger <= progress < n.end:
                notice = n.text
        callbacks, clock = self.callbacks, self.clock
        if clock is not None:
            clock.lap(Phase.OBSERVATION)
        for cb in callbacks:
            cb.on_render_start(self)
        bev = self.renderer.render((state.x, state.y, state.yaw), (params.length, params.width),
                                   frame.vehicles, frame.pedestrians, frame.tl_states)
        for cb in callbacks:
            cb.on_render_end(self)
        if clock is not None:
            clock.lap(Phase.BEV)
        world = None
        if self.privileged:
            world = World(net=self.net, ego=state, lane=frame.lane, lane_pos=frame.lane_pos,
                          vehicles=frame.vehicles, pedestrians=frame.pedestrians,
                          tl_states=frame.tl_states, route=self.ego_route if self.needs_route else None,
                          progress=progress)
        text, iid = self._shown()
        answer = self.navigator.shown(frame.t, self.k_instr) if self.navigator is not None else None
        if answer is not None:
            text, iid = answer
        obs = Observation(t=frame.t, bev=bev, speed=state.speed, instruction=text, instruction_id=iid,
                          notice=notice, world=world, answer=answer is not None,
                          compass=wrap_angle(state.yaw))
        for cb in callbacks:
            cb.on_observation(self, obs)
        if clock is not None:
            clock.lap(Phase.OBSERVATION)
        return obs

    # ------------------------------------------------------------------ results
    def log(self, agent: str) -> EpisodeLog:
        """The episode log so far (complete once the episode has ended), under ``agent``."""
        cols, instructions, scenario = self.recorder.cols, self.instructions, self.scenario
        return EpisodeLog(
            route_id=scenario.route_id, agent=agent,
            family=instructions.family, k=instructions.k, seed=scenario.seed, step_length=self.dt,
            route_length=self.route.length, t=tuple(cols["t"]), x=tuple(cols["x"]), y=tuple(cols["y"]),
            yaw=tuple(cols["yaw"]), speed=tuple(cols["speed"]), progress=tuple(cols["progress"]),
            instruction=tuple(cols["instruction"]), outside=tuple(cols["outside"]),
            route_dist=tuple(cols["route_dist"]), events=tuple(self.recorder.events),
            traffic_speed=tuple(cols["traffic_speed"]), speed_limit=tuple(cols["speed_limit"]),
            termination=self.termination, termination_t=self.term_t, message=self.message,
            route=self.polyline,
            guard=tuple(self.guarded.decisions) if self.guarded is not None else (),
            asks=tuple(self.navigator.asks) if self.navigator is not None else (),
        )


def _route_baseline(scenario: Scenario, instructions: InstructionSet, baseline: InstructionSet | None,
                    why: str) -> InstructionSet:
    """The route's baseline sequence (``instructions`` itself when it is the baseline); an
    InputError saying ``why`` it is needed without it."""
    if baseline is None and instructions.family == Family.BASELINE:
        baseline = instructions
    if baseline is None or baseline.family != Family.BASELINE or baseline.route_id != scenario.route_id:
        raise InputError(Field("baseline"), scenario.route_id, why,
                         "pass the baseline sequence of this route")
    return baseline


def _navigator(scenario: Scenario, net: RoadNet, instructions: InstructionSet,
               baseline: InstructionSet | None, delay: float) -> Navigator:
    """The navigator of an episode with asking on; an InputError without the route's baseline."""
    baseline = _route_baseline(scenario, instructions, baseline,
                               "asking needs the route's baseline instructions, whose words answer the agent")
    return Navigator(extract_maneuvers(scenario, net), baseline.instructions, delay)


def run_episode(scenario: Scenario, instructions: InstructionSet, agent: Agent,
                options: RunOptions = RunOptions(),  # noqa: B008
                callbacks: Sequence[EpisodeCallback] = (), guard: Guard | None = None,
                baseline: InstructionSet | None = None, clock: PhaseClock | None = None) -> EpisodeLog:
    """Drive one episode with ``agent`` and return its log (:class:`icrsumo.core.types.EpisodeLog`).

    The agent is reset with the episode's :class:`EpisodeInfo`, then acts on every observation;
    ``callbacks`` (:mod:`icrsumo.sim.callbacks`) attach side effects such as timings or video.
    A privileged agent (``privileged = True``) sees the :class:`World` view, with the route only
    when it also declares ``needs_route = True``. An agent with an ``episode_calls()`` method
    (one that asks a language model) has what it returns stored as the log's ``model_calls``.
    With a ``guard`` (:mod:`icrsumo.guards`) each new instruction passes it before the agent
    sees it; its decisions are the log's ``guard`` and the log is named ``AGENT+guard:NAME``
    (``AGENT+guard:NAME+navigator`` under ``options.on_block`` navigator).
    With ``options.asking`` the navigator answers the agent's asks in the words of ``baseline``
    (the route's baseline sequence); they are the log's ``asks``. With a ``clock``
    (:class:`~icrsumo.sim.callbacks.PhaseClock`) the episode's wall time is split into its
    phases (:class:`~icrsumo.core.vocab.Phase`); the log is the same.
    An exception raised while the episode runs (by the agent, its guard, an action the checks
    refuse) ends the episode and is raised again (:func:`drive_episode` returns it instead,
    beside the log up to the last completed step)."""
    log, error = drive_episode(scenario, instructions, agent, options, callbacks, guard, baseline, clock)
    if error is not None:
        raise error
    return log


def drive_episode(scenario: Scenario, instructions: InstructionSet, agent: Agent,
                  options: RunOptions = RunOptions(),  # noqa: B008
                  callbacks: Sequence[EpisodeCallback] = (), guard: Guard | None = None,
                  baseline: InstructionSet | None = None, clock: PhaseClock | None = None
                  ) -> tuple[EpisodeLog, BaseException | None]:
    """:func:`run_episode` that returns what the episode raised instead of raising it: the log
    and None, or, when the agent's ``reset`` or ``act``, its guard's calls or anything else in
    the loop raised (a timeout its calls are under included), the log up to the last completed
    step (termination agent_error, the error in one line as its message:
    :func:`~icrsumo.core.errors.describe`; no step when ``reset`` raised) and that exception.
    The user's Ctrl-C during an evaluation (:class:`~icrsumo.core.errors.Interrupted`) is raised."""
    error: BaseException | None = None
    with Episode(scenario, instructions, options, privileged=bool(getattr(agent, "privileged", False)),
                 needs_route=bool(getattr(agent, "needs_route", False)), callbacks=callbacks,
                 guard=guard, baseline=baseline, clock=clock) as ep:
        if clock is not None:
            clock.lap(Phase.EPISODE_SETUP)
        try:
            _loop(ep, agent, clock)
        except Interrupted:
            raise
        except BaseException as err:  # noqa: BLE001 - the agent's code may raise anything (sys.exit too)
            error = err
            ep.abort(describe(err))
    if clock is not None:
        clock.lap(Phase.SUMO_START)  # SUMO closed
    name = getattr(agent, "name", type(agent).__name__)
    log = ep.log(name if ep.guarded is None else guarded_name(name, ep.guarded.name, ep.guarded.on_block))
    calls = getattr(agent, "episode_calls", None)  # an agent that asks a language model
    if callable(calls):
        try:
            log = replace(log, model_calls=tuple(calls()))
        except Exception:
            if error is None:
                raise
    return log, error


def _loop(ep: Episode, agent: Agent, clock: PhaseClock | None) -> None:
    """Reset ``agent``, start ``ep`` and let the agent act on each observation until it ends."""
    agent.reset(ep.info)
    if clock is not None:
        clock.lap(Phase.AGENT_LOAD)
    obs = ep.start()
    hooks = ep.callbacks[1:]  # the recorder needs no act hooks
    while obs is not None:
        for cb in hooks:
            cb.on_act_start(ep, obs)
        action = agent.act(obs)
        for cb in hooks:
            cb.on_act_end(ep, action)
        if clock is not None:
            clock.lap(Phase.ACT)
        obs = ep.step(action)
