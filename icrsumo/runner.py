"""One closed-loop episode: scenario x instruction sequence x agent -> EpisodeLog.

Loop per simulation step (``step_length`` s, 0.05 s = 20 Hz as the Leaderboard):
the agent acts every ``control_every`` steps (default 2: 10 Hz) on an observation (BEV raster,
speed, active instruction with ``[x]`` filled, notice); its action (controls or ego-frame
waypoints through the built-in controller) drives the kinematic bicycle model; the ego is
placed in SUMO with ``moveToXY(keepRoute=2)``; SUMO steps; the runner reads collisions, the
ego's lane and teleports, and records the step. The surroundings (vehicles and pedestrians within
60 m, every traffic light's state) are read, and the BEV rendered, only on the steps where the
agent observes; the red-light check keeps the states of the lights ahead of the ego.
``RunOptions(timings=LoopTimings())`` splits an episode's wall time (tools/benchmark.py).

Instructions are issued online from the ego's progress (its projection on the route polyline,
searched near the previous progress so that a route passing close to itself cannot jump):
the active instruction is the last one whose trigger (m) has been passed, the same triggers for
every variant. Infractions (collisions with vehicles / pedestrians de-duplicated per actor
contact, roadside, red lights, stop signs, driving outside the route's lanes, wrong way) and
run-ending rules (:mod:`icrsumo.termination`) follow Leaderboard 1.0.
"""

from __future__ import annotations

import bisect
import math
import time
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import numpy as np

from .agents.base import Action, Agent, EpisodeInfo, Observation, World, validate_action
from .control import WaypointController, WaypointPath
from .dynamics import Control, EgoState, VehicleParams, step
from .networks import RoadNet, load_net
from .render import BevRenderer, BevSpec
from .scenario import Scenario
from .sim import EGO_ID, SumoSession, sumo_constants
from .termination import TerminationMonitor, route_timeout
from .types import EgoRoute, EpisodeLog, Event, InstructionSet, LanePos

#: SUMO steps per agent decision (0.05 s x 2 = 10 Hz)
CONTROL_EVERY = 2
#: radius (m) of the context subscription around the ego
CONTEXT_RADIUS = 60.0
#: an approach to a stop sign counts as stopped below this speed (m/s) within this distance (m)
STOP_SPEED, STOP_ZONE = 0.1, 15.0
#: wrong way: heading off the lane direction by more than this (rad)
WRONG_WAY_RAD = math.radians(100.0)


@dataclass
class LoopTimings:
    """Wall-clock split of episodes (s, ``time.perf_counter``), filled by :func:`run_episode`
    when given as ``RunOptions.timings``; it accumulates over the episodes it is passed to.

    ``setup_s``: SUMO start, traffic warm-up and ego insertion; ``loop_s``: the closed loop
    over ``steps`` steps (everything per step: sensors, BEV, the agent, controller, SUMO);
    ``render_s`` over ``frames`` BEV frames; ``act_s`` over ``acts`` calls of ``agent.act``.
    """

    setup_s: float = 0.0
    loop_s: float = 0.0
    steps: int = 0
    render_s: float = 0.0
    frames: int = 0
    act_s: float = 0.0
    acts: int = 0


@dataclass(frozen=True)
class RunOptions:
    """Episode options: agent rate (``control_every`` SUMO steps per agent decision), BEV
    spec, optional BEV video path, optional :class:`LoopTimings` to fill (benchmarks)."""

    control_every: int = CONTROL_EVERY
    bev: BevSpec = BevSpec()
    video: Path | None = None
    timings: LoopTimings | None = field(default=None, compare=False)


@cache
def _renderer(net_path: str, spec: BevSpec) -> BevRenderer:
    return BevRenderer(load_net(Path(net_path)), spec)


#: routes with at most this many segments are projected in plain Python (numpy's per-call
#: overhead dominates on a few segments), longer ones on arrays
_SMALL_ROUTE = 48
#: relative slack of the squared-distance preselection in _Route._locate_small
_PRESELECT = 1e-9


class _Route:
    """The route polyline with windowed projection (progress) and distance queries.

    :meth:`locate` runs every simulation step. Its values are those of the plain per-segment
    formula evaluated on arrays (``t = clip(((p - a) . ab) / max(|ab|^2, 1e-9), 0, 1)``,
    ``d = hypot(a + ab t - p)``), bit for bit: the same floating-point operations in the same
    order, with distances from ``np.hypot``."""

    def __init__(self, poly: np.ndarray) -> None:
        self.a = poly[:-1]
        self.b = poly[1:]
        ab = self.b - self.a
        self.len = np.hypot(ab[:, 0], ab[:, 1])
        self.ab = ab
        self.cum = np.concatenate([[0.0], np.cumsum(self.len)])
        self.total = float(self.cum[-1])
        self._a2 = np.ascontiguousarray(self.a.T)     # (2, N): x row, y row
        self._ab2 = np.ascontiguousarray(ab.T)
        self._den = np.maximum(self.len ** 2, 1e-9)
        self._cum_list = self.cum.tolist()
        self._len_list = self.len.tolist()
        self._segs = list(zip(self.a[:, 0].tolist(), self.a[:, 1].tolist(), ab[:, 0].tolist(),
                              ab[:, 1].tolist(), self._den.tolist()))

    def _window(self, progress: float) -> tuple[int, int]:
        """Segments k in [lo, hi) with cum[k + 1] >= progress - 20 and cum[k] <= progress + 40
        (a contiguous range: cum is non-decreasing)."""
        cum = self._cum_list
        lo = bisect.bisect_left(cum, progress - 20.0, 1) - 1
        hi = min(bisect.bisect_right(cum, progress + 40.0), len(cum) - 1)
        return lo, hi

    def locate(self, x: float, y: float, progress: float) -> tuple[float, float]:
        """(route position near ``progress``, distance to the whole route) in m: the nearest
        projection among the segments within [progress - 20, progress + 40] m if it is within
        15 m (else ``progress``), and the distance to the nearest point of the route."""
        if len(self._segs) <= _SMALL_ROUTE:
            return self._locate_small(x, y, progress)
        p = np.array(((x,), (y,)))
        pa = (p - self._a2) * self._ab2
        t = pa[0] + pa[1]
        t /= self._den
        np.maximum(t, 0.0, out=t)                    # = np.clip(t, 0, 1), t is never NaN
        np.minimum(t, 1.0, out=t)
        q = self._ab2 * t
        q += self._a2
        q -= p
        d_all = np.hypot(q[0], q[1])
        lo, hi = self._window(progress)
        if lo < hi:
            k = lo + int(d_all[lo:hi].argmin())
            s_here = self._cum_list[k] + t.item(k) * self._len_list[k] if d_all.item(k) < 15.0 else progress
        else:
            s_here = progress
        return s_here, float(d_all.min())

    def _locate_small(self, x: float, y: float, progress: float) -> tuple[float, float]:
        """:meth:`locate` in plain Python. Distances come from ``np.hypot``, but only for the
        segments whose squared distance is within a relative 1e-9 of the smallest (of the
        window, of the route): the others are farther by far more than hypot's rounding, so
        the argmin (first minimum) and the minimum are those of the full array."""
        lo, hi = self._window(progress)
        ts, qs, e2 = [], [], []
        for ax, ay, abx, aby, den in self._segs:
            t = ((x - ax) * abx + (y - ay) * aby) / den
            t = 0.0 if t < 0.0 else 1.0 if t > 1.0 else t
            qx, qy = ax + abx * t - x, ay + aby * t - y
            ts.append(t)
            qs.append((qx, qy))
            e2.append(qx * qx + qy * qy)
        dist = [math.nan] * len(e2)
        hypot = np.hypot
        best = []
        for a, b in ((lo, hi), (0, len(e2))):
            if a >= b:
                best.append(-1)
                continue
            cut = min(e2[a:b])
            cut = cut * (1.0 + _PRESELECT) if cut >= 1e-280 else math.inf  # tiny squares: all
            k_best, d_best = -1, math.inf
            for k in range(a, b):
                if e2[k] <= cut:
                    d = dist[k]
                    if d != d:  # not computed yet
                        d = dist[k] = float(hypot(*qs[k]))
                    if d < d_best:
                        k_best, d_best = k, d
            best.append(k_best)
        k = best[0]
        near = k >= 0 and dist[k] < 15.0
        return (self._cum_list[k] + ts[k] * self._len_list[k] if near else progress), dist[best[1]]


def _ego_route(sc: Scenario) -> EgoRoute:
    m = sc.manifest
    st, en = m["ego"]["start"], m["ego"]["end"]
    return EgoRoute(
        edges=tuple(m["ego"]["edges"]), lanes=tuple(tuple(x) for x in m["ego"]["lanes"]),
        lane_path=tuple(m["ego"]["lane_path"]), start=LanePos(**st), end=LanePos(**en),
        polyline=sc.polyline, length=sc.length, junctions=(), lane_changes=(),
    )


def _corners(st: EgoState, size: tuple[float, float]) -> np.ndarray:
    """The ego footprint's four corners (4, 2) m; ``size`` = (length, width) m."""
    c, s = math.cos(st.yaw), math.sin(st.yaw)
    hl, hw = 0.5 * size[0], 0.5 * size[1]
    local = np.array([[hl, hw], [hl, -hw], [-hl, -hw], [-hl, hw]])
    return np.stack([st.x + local[:, 0] * c - local[:, 1] * s, st.y + local[:, 0] * s + local[:, 1] * c], 1)


def _angle_diff(a: float, b: float) -> float:
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


def _off_corners(st: EgoState, size: tuple[float, float], count_off) -> int:
    """How many corners of the ego footprint (:func:`_corners`, same arithmetic) are off the
    drivable area (``count_off(points) -> int``: :meth:`BevRenderer.count_off`)."""
    c, s = math.cos(st.yaw), math.sin(st.yaw)
    hl, hw = 0.5 * size[0], 0.5 * size[1]
    x, y = st.x, st.y
    return count_off([(x + lx * c - ly * s, y + lx * s + ly * c)
                      for lx, ly in ((hl, hw), (hl, -hw), (-hl, -hw), (-hl, hw))])


class _LaneHeading:
    """Lane heading (rad) at a lane position: ``RoadNet.lane_pose(lane, pos)[2]`` with the
    per-lane tables built once (same cumulative lengths, same segment choice)."""

    def __init__(self, net: RoadNet) -> None:
        self.net = net
        self._tables: dict[str, tuple | None] = {}

    def _table(self, lane: str) -> tuple | None:
        shape = self.net.lane_shape[lane]
        if len(shape) < 2:
            return None
        cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(shape, axis=0).T))])
        heads = [math.atan2(shape[k + 1][1] - shape[k][1], shape[k + 1][0] - shape[k][0])
                 for k in range(len(shape) - 1)]
        return cum.tolist(), float(cum[-1]), max(self.net.lane_length[lane], 1e-9), heads

    def __call__(self, lane: str, pos: float) -> float:
        tab = self._tables.get(lane, False)
        if tab is False:
            tab = self._tables[lane] = self._table(lane)
        if tab is None:
            return self.net.lane_pose(lane, pos)[2]
        cum, total, length, heads = tab
        s = min(max(pos * total / length, 0.0), total)
        k = min(max(bisect.bisect_right(cum, s) - 1, 0), len(heads) - 1)
        return heads[k]


class _Sensors:
    """Infraction detection from SUMO's view of the ego, step by step."""

    def __init__(self, net: RoadNet, route_edges: set[str]) -> None:
        self.net = net
        self.route_edges = route_edges
        self.prev_lane = ""
        self.touching: set[str] = set()
        self.stopped: set[str] = set()
        self.roadside = False
        self.wrong = False
        self.heading = _LaneHeading(net)
        self._inside: dict[str, bool] = {}
        self._tls_ahead: dict[str, tuple[str, ...]] = {}

    def inside(self, lane: str) -> bool:
        got = self._inside.get(lane)
        if got is None:
            got = self._inside[lane] = self._inside_uncached(lane)
        return got

    def _inside_uncached(self, lane: str) -> bool:
        if not lane:
            return False
        if lane.startswith(":"):
            a, b = self.net.via_edges.get(lane, ("", ""))
            return a in self.route_edges and b in self.route_edges
        return lane.rsplit("_", 1)[0] in self.route_edges

    def tls_ahead(self) -> tuple[str, ...]:
        """Traffic lights whose state the red-light check of the next step may read: those of
        the connections from ``prev_lane`` (none when it is junction-internal)."""
        lane = self.prev_lane
        got = self._tls_ahead.get(lane)
        if got is None:
            out: set[str] = set()
            if lane and not lane.startswith(":"):
                edge, _, idx = lane.rpartition("_")
                i = int(idx)
                for nxt in self.net.successors.get(edge, ()):
                    out.update(c.tls for c in self.net.connections[(edge, nxt)]
                               if c.tls and c.from_lane == i)
            got = self._tls_ahead[lane] = tuple(sorted(out))
        return got

    def lane_events(self, t: float, pos: float, lane: str, lane_pos: float, st: EgoState,
                    tl_prev: dict[str, str], count_off, size: tuple[float, float]) -> list[Event]:
        """Events of this step; ``tl_prev`` holds (at least) the previous step's states of the
        lights :meth:`tls_ahead` named then; ``count_off(points) -> int`` counts points off
        the drivable area."""
        ev: list[Event] = []
        net = self.net
        # stop-sign bookkeeping: stopped within the last STOP_ZONE m of a lane
        if lane and not lane.startswith(":") and st.speed < STOP_SPEED and \
                net.lane_length.get(lane, 0.0) - lane_pos <= STOP_ZONE:
            self.stopped.add(lane)
        prev = self.prev_lane
        if prev and not prev.startswith(":") and lane.startswith(":"):
            edge = prev.rsplit("_", 1)[0]
            idx = int(prev.rsplit("_", 1)[1])
            for nxt in net.successors.get(edge, ()):
                for c in net.connections[(edge, nxt)]:
                    if c.from_lane == idx and c.via == lane:
                        if c.tls:
                            state = tl_prev.get(c.tls, "")
                            if 0 <= c.link_index < len(state) and state[c.link_index] in "rR":
                                ev.append(Event("red_light", t, pos, c.tls, st.x, st.y))
                        elif c.state in ("s", "w") and prev not in self.stopped:
                            ev.append(Event("stop_sign", t, pos, net.edge_to_node.get(edge, ""), st.x, st.y))
        if lane and lane != prev and not lane.startswith(":"):
            self.stopped.discard(lane)  # a fresh approach to this lane's end
        # roadside: the footprint left the drivable area (two corners or more off it)
        off = _off_corners(st, size, count_off) >= 2
        if off and not self.roadside:
            ev.append(Event("collision_static", t, pos, "roadside", st.x, st.y))
        self.roadside = off
        # wrong way
        wrong = False
        if lane and lane in net.lane_shape:
            heading = self.heading(lane, lane_pos)
            wrong = _angle_diff(heading, st.yaw) > WRONG_WAY_RAD
        if wrong and not self.wrong:
            ev.append(Event("wrong_way", t, pos, lane, st.x, st.y))
        self.wrong = wrong
        if lane:
            self.prev_lane = lane
        return ev

    def collisions(self, t: float, pos: float, st: EgoState, colls, persons: set[str]) -> list[Event]:
        ev = []
        now = set()
        for c in colls:
            if c.collider == EGO_ID:
                other = c.victim
            elif c.victim == EGO_ID:
                other = c.collider
            else:
                continue
            now.add(other)
            if other not in self.touching:
                kind = "collision_pedestrian" if other in persons else "collision_vehicle"
                ev.append(Event(kind, t, pos, other, st.x, st.y))
        self.touching = now
        return ev


def _active(triggers: list[float], progress: float) -> int:
    return bisect.bisect_right(triggers, progress + 1e-9) - 1


class Episode:
    """One closed-loop episode as a steppable object: the loop of :func:`run_episode`, which
    drives it, and of the Gymnasium environment (:mod:`icrsumo.env`).

    ``start()`` starts SUMO (warm-up, ego insertion) and returns the first
    :class:`Observation`; ``step(action)`` checks the action (:func:`validate_action`), holds it
    for ``control_every`` simulation steps and returns the next observation, or None once the
    episode has ended (``termination`` says why). ``log(agent)`` is the :class:`EpisodeLog` so
    far. ``close()`` (or leaving the ``with`` block) ends the SUMO session and the video.
    ``privileged``: observations carry the :class:`World` view (built-in agents only).
    """

    def __init__(self, scenario: Scenario, instructions: InstructionSet,
                 opts: RunOptions = RunOptions(), privileged: bool = False) -> None:  # noqa: B008
        self.scenario, self.instructions = scenario, instructions
        self.opts, self.privileged = opts, privileged
        self.tc = sumo_constants()
        self.net = load_net(scenario.net)
        m = scenario.manifest
        self.params = VehicleParams(length=float(m["ego"]["length"]), width=float(m["ego"]["width"]))
        self.route = _Route(np.asarray(scenario.polyline, dtype=float))
        self.ego_route = _ego_route(scenario)
        self.renderer = _renderer(str(scenario.net), opts.bev)
        self.dt = float(m.get("step_length", 0.05))
        self.instr = instructions.instructions
        self.triggers = [i.trigger for i in self.instr]
        self.texts = [i.rendered() for i in self.instr]
        self.notices = instructions.notices
        self.sensors = _Sensors(self.net, set(self.ego_route.edges))
        self.controller = WaypointController(self.params)
        #: what the agent is told at reset
        self.info = EpisodeInfo(route_id=scenario.route_id, town=scenario.town, net=str(scenario.net),
                                step_length=self.dt, control_dt=self.dt * opts.control_every,
                                seed=scenario.seed)
        #: the log's per-step columns so far
        self.cols: dict[str, list] = {k: [] for k in ("t", "x", "y", "yaw", "speed", "progress",
                                                      "instruction", "outside", "route_dist")}
        self.events: list[Event] = []
        self.termination, self.term_t, self.message = "sim_error", 0.0, ""
        self.done = False
        self.progress = 0.0
        self.sim: SumoSession | None = None
        self.setup_end = 0.0  # perf_counter() when start() finished its setup (timings only)
        self.video = None
        self._frame = None
        self.i = 0

    def __enter__(self) -> Episode:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """End the video and the SUMO session (idempotent)."""
        try:
            if self.video is not None:
                self.video.close()
                self.video = None
        finally:
            if self.sim is not None:
                self.sim.close()
                self.sim = None

    def _sim_error(self, err: Exception) -> None:
        if not (type(err).__module__.startswith("libsumo") or "TraCI" in type(err).__name__):
            raise err
        self.termination, self.term_t = "sim_error", self.sim.time
        self.message = f"{type(err).__name__}: {err}"
        self.events.append(Event("sim_error", self.term_t, 0.0, self.message))
        self.done = True

    def start(self) -> Observation | None:
        """Start SUMO, warm up, insert the ego; the first observation (None: ended at once)."""
        timings = self.opts.timings
        t0 = time.perf_counter() if timings is not None else 0.0
        if self.opts.video is not None:
            from .render import VideoWriter

            self.video = VideoWriter(self.opts.video)
        self.sim = SumoSession(self.scenario).__enter__()
        sim, ls, tc, scenario, params = self.sim, self.sim.ls, self.tc, self.scenario, self.params
        try:
            sim.run_until(scenario.ego_depart)
            sx, sy, sh = scenario.start  # front bumper on the start lane
            self.state = EgoState(sx - 0.5 * params.length * math.cos(sh),
                                  sy - 0.5 * params.length * math.sin(sh), sh)
            lane_index = scenario.start_lane.rsplit("_", 1)[1]
            ls.vehicle.add(EGO_ID, "ego_route", typeID="ego", depart="now", departLane=lane_index,
                           departPos=f"{scenario.start_pos:.2f}", departSpeed="0")
            ls.vehicle.setSpeedMode(EGO_ID, 0)
            ls.vehicle.setLaneChangeMode(EGO_ID, 0)
            ls.vehicle.moveToXY(EGO_ID, "", -1, sx, sy, 90.0 - math.degrees(sh), 2)
            ls.simulationStep()
            ls.vehicle.subscribe(EGO_ID, [tc.VAR_LANE_ID, tc.VAR_LANEPOSITION])
            ls.vehicle.subscribeContext(EGO_ID, tc.CMD_GET_VEHICLE_VARIABLE, CONTEXT_RADIUS,
                                        [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_LENGTH, tc.VAR_WIDTH])
            ls.vehicle.subscribeContext(EGO_ID, tc.CMD_GET_PERSON_VARIABLE, CONTEXT_RADIUS,
                                        [tc.VAR_POSITION])
            self.tls_ids = ls.trafficlight.getIDList()
            for tl in self.tls_ids:
                ls.trafficlight.subscribe(tl, [tc.TL_RED_YELLOW_GREEN_STATE])
            self.monitor = TerminationMonitor(self.route.total, sim.time)
            self.progress, self.tl_prev = 0.0, {}
            self.action = Action(control=Control(brake=1.0))
            self._path = None
            self.n_max = int((route_timeout(self.route.total) + 10.0) / self.dt) + 10
            self.i = 0
            if timings is not None:
                self.setup_end = time.perf_counter()
                timings.setup_s += self.setup_end - t0
            return self._advance()
        except Exception as err:  # libsumo raises TraCIException and friends
            self._sim_error(err)
            return None

    def step(self, action: Action) -> Observation | None:
        """Hold ``action`` (checked: AgentError when invalid) until the next decision; its
        observation, or None once the episode has ended."""
        if self.done or self.sim is None:
            raise RuntimeError("the episode has ended (or was never started)")
        self.action = validate_action(action)
        # the waypoints' polyline, prepared once for the steps the action is held
        self._path = None if self.action.control is not None else WaypointPath(self.action.waypoints)
        if self.video is not None and self._frame is not None:
            self.video.add(*self._frame)
        self._frame = None
        try:
            self._apply()
            return self._advance()
        except Exception as err:
            self._sim_error(err)
            return None

    def _apply(self) -> None:
        """The held action for one simulation step: controls, bicycle model, SUMO step."""
        action, state, params, dt = self.action, self.state, self.params, self.dt
        control = action.control if action.control is not None else self.controller.control(
            self._path, state.speed, dt, action.target_speed)
        state = self.state = step(state, control, dt, params)
        fx, fy = state.front(params.length)
        ls = self.sim.ls
        ls.vehicle.moveToXY(EGO_ID, "", -1, fx, fy, 90.0 - math.degrees(state.yaw), 2)
        # the states the next step's red-light check may read (those of the lights ahead)
        tl_result, tl_var = ls.trafficlight.getSubscriptionResults, self.tc.TL_RED_YELLOW_GREEN_STATE
        self.tl_prev = {tl: tl_result(tl)[tl_var] for tl in self.sensors.tls_ahead()}
        ls.simulationStep()
        self.i += 1

    def _advance(self) -> Observation | None:
        """Simulation steps until the next decision (its observation) or the end (None)."""
        while True:
            if self.i >= self.n_max:
                self.termination, self.term_t, self.done = "route_timeout", self.sim.time, True
                return None
            if self._record_step():
                return None
            if self.i % self.opts.control_every == 0:
                return self._observation()
            self._apply()

    def _record_step(self) -> bool:
        """Read SUMO's state, detect events, record the step; True when the episode ended.

        Runs every simulation step, so it reads only what every step needs (the ego's lane,
        collisions, teleports); the surroundings and the traffic lights are read only for an
        observation (:meth:`_observation`)."""
        sim, ls, tc, state = self.sim, self.sim.ls, self.tc, self.state
        sensors, params = self.sensors, self.params
        t = sim.time
        sub = ls.vehicle.getSubscriptionResults(EGO_ID)
        # results exist only while the ego does (after a moveToXY it is also in getIDList())
        if not sub and EGO_ID not in ls.vehicle.getIDList():
            self.events.append(Event("ego_teleport", t, self.progress, "", state.x, state.y))
            self.termination, self.term_t, self.done = "stuck", t, True
            return True
        lane, lane_pos = sub.get(tc.VAR_LANE_ID, ""), float(sub.get(tc.VAR_LANEPOSITION, 0.0))
        s_here, rdist = self.route.locate(state.x, state.y, self.progress)
        progress = self.progress = max(self.progress, s_here)
        step_events = []
        colls = ls.simulation.getCollisions()
        if colls:
            persons = set(ls.person.getIDList())
            step_events += sensors.collisions(t, progress, state, colls, persons)
        step_events += sensors.lane_events(t, progress, lane, lane_pos, state, self.tl_prev,
                                           self.renderer.count_off, (params.length, params.width))
        teleports = ls.simulation.getStartingTeleportIDList()
        if teleports:
            step_events += [Event("teleport_background", t, progress, vid) for vid in teleports
                            if vid != EGO_ID]
        if step_events:
            self.events += step_events
        k_instr = _active(self.triggers, progress)
        cols = self.cols
        cols["t"].append(t)
        cols["x"].append(state.x)
        cols["y"].append(state.y)
        cols["yaw"].append(state.yaw)
        cols["speed"].append(state.speed)
        cols["progress"].append(progress)
        cols["instruction"].append(self.instr[k_instr].id if k_instr >= 0 else -1)
        cols["outside"].append(0 if sensors.inside(lane) and not sensors.wrong else 1)
        cols["route_dist"].append(rdist)
        self.lane, self.lane_pos, self.k_instr = lane, lane_pos, k_instr
        done = self.monitor.update(t, progress, rdist, state.speed, step_events)
        if done:
            self.termination, self.term_t, self.done = done, t, True
            return True
        return False

    def _surroundings(self) -> tuple[np.ndarray, np.ndarray, dict[str, str]]:
        """Vehicles (N, 5: centre x, y, yaw, length, width), pedestrians (M, 2) near the ego
        (the context subscription) and every traffic light's state, at the current step."""
        ls, tc = self.sim.ls, self.tc
        ctx = ls.vehicle.getContextSubscriptionResults(EGO_ID) or {}
        rows, peds = [], []
        p_var, a_var, l_var, w_var = tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_LENGTH, tc.VAR_WIDTH
        cos, sin, radians = math.cos, math.sin, math.radians
        for vid, v in ctx.items():
            if a_var in v:
                if vid == EGO_ID:
                    continue
                yaw = radians(90.0 - v[a_var])
                ln = v[l_var]
                fx, fy = v[p_var]
                rows.append((fx - 0.5 * ln * cos(yaw), fy - 0.5 * ln * sin(yaw), yaw, ln, v[w_var]))
            else:
                peds.append(v[p_var])
        vehicles = np.array(rows, dtype=float).reshape(-1, 5)
        pedestrians = np.array(peds, dtype=float).reshape(-1, 2)
        tl_all = ls.trafficlight.getAllSubscriptionResults()
        tl_var = tc.TL_RED_YELLOW_GREEN_STATE
        tl_states = {tl: tl_all[tl][tl_var] for tl in self.tls_ids}
        return vehicles, pedestrians, tl_states

    def _observation(self) -> Observation:
        """The agent's observation at the current step (BEV, speed, instruction, notice)."""
        state, params, progress, k_instr = self.state, self.params, self.progress, self.k_instr
        notice = ""
        for n in self.notices:
            if n.trigger <= progress < n.end:
                notice = n.text
        vehicles, pedestrians, tl_states = self._surroundings()
        timings = self.opts.timings
        t0 = time.perf_counter() if timings is not None else 0.0
        bev = self.renderer.render((state.x, state.y, state.yaw), (params.length, params.width),
                                   vehicles, pedestrians, tl_states)
        if timings is not None:
            timings.render_s += time.perf_counter() - t0
            timings.frames += 1
        world = None
        if self.privileged:
            world = World(net=self.net, ego=state, lane=self.lane, lane_pos=self.lane_pos,
                          vehicles=vehicles, pedestrians=pedestrians, tl_states=tl_states,
                          route=self.ego_route, progress=progress)
        obs = Observation(t=self.cols["t"][-1], bev=bev, speed=state.speed,
                          instruction=self.texts[k_instr] if k_instr >= 0 else "",
                          instruction_id=self.instr[k_instr].id if k_instr >= 0 else -1,
                          notice=notice, world=world)
        if self.video is not None:
            self._frame = (bev, obs.instruction, notice, state.speed)
        return obs

    def log(self, agent: str) -> EpisodeLog:
        """The episode log so far (complete once the episode has ended), under ``agent``."""
        cols, instructions, scenario = self.cols, self.instructions, self.scenario
        return EpisodeLog(
            route_id=scenario.route_id, agent=agent,
            family=instructions.family, k=instructions.k, seed=scenario.seed, step_length=self.dt,
            route_length=self.route.total, t=tuple(cols["t"]), x=tuple(cols["x"]), y=tuple(cols["y"]),
            yaw=tuple(cols["yaw"]), speed=tuple(cols["speed"]), progress=tuple(cols["progress"]),
            instruction=tuple(cols["instruction"]), outside=tuple(cols["outside"]),
            route_dist=tuple(cols["route_dist"]), events=tuple(self.events), termination=self.termination,
            termination_t=self.term_t, message=self.message,
        )


def run_episode(scenario: Scenario, instructions: InstructionSet, agent: Agent,
                opts: RunOptions = RunOptions()) -> EpisodeLog:  # noqa: B008
    """Drive one episode and return its log (see :class:`icrsumo.types.EpisodeLog`)."""
    timings = opts.timings
    with Episode(scenario, instructions, opts, privileged=getattr(agent, "privileged", False)) as ep:
        agent.reset(ep.info)
        if timings is None:
            obs = ep.start()
            while obs is not None:
                obs = ep.step(agent.act(obs))
        else:
            obs = ep.start()
            while obs is not None:
                t0 = time.perf_counter()
                action = agent.act(obs)
                timings.act_s += time.perf_counter() - t0
                timings.acts += 1
                obs = ep.step(action)
            timings.loop_s += time.perf_counter() - (ep.setup_end or time.perf_counter())
            timings.steps += len(ep.cols["t"])
    return ep.log(getattr(agent, "name", type(agent).__name__))
