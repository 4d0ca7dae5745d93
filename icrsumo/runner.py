"""One closed-loop episode: scenario x instruction sequence x agent -> EpisodeLog.

Loop per simulation step (``step_length`` s, 0.05 s = 20 Hz as the Leaderboard):
the agent acts every ``control_every`` steps (default 2: 10 Hz) on an observation (BEV raster,
speed, active instruction with ``[x]`` filled, notice); its action (controls or ego-frame
waypoints through the built-in controller) drives the kinematic bicycle model; the ego is
placed in SUMO with ``moveToXY(keepRoute=2)``; SUMO steps; the runner reads collisions, the
ego's lane, traffic lights and teleports, and records the step.

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
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np

from .agents.base import Action, Agent, EpisodeInfo, Observation, World, validate_action
from .control import WaypointController
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


@dataclass(frozen=True)
class RunOptions:
    """Episode options: agent rate, BEV spec, optional BEV video path."""

    control_every: int = CONTROL_EVERY
    bev: BevSpec = BevSpec()
    video: Path | None = None


@cache
def _renderer(net_path: str, spec: BevSpec) -> BevRenderer:
    return BevRenderer(load_net(Path(net_path)), spec)


class _Route:
    """The route polyline with windowed projection (progress) and distance queries."""

    def __init__(self, poly: np.ndarray) -> None:
        self.a = poly[:-1]
        self.b = poly[1:]
        ab = self.b - self.a
        self.len = np.hypot(ab[:, 0], ab[:, 1])
        self.ab = ab
        self.cum = np.concatenate([[0.0], np.cumsum(self.len)])
        self.total = float(self.cum[-1])

    def _proj(self, p: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ab, a = self.ab[idx], self.a[idx]
        t = np.clip(((p - a) * ab).sum(axis=1) / np.maximum(self.len[idx] ** 2, 1e-9), 0.0, 1.0)
        q = a + ab * t[:, None]
        return np.hypot(*(q - p).T), self.cum[idx] + t * self.len[idx]

    def locate(self, x: float, y: float, progress: float) -> tuple[float, float]:
        """(route position near ``progress``, distance to the whole route) in m."""
        p = np.array([x, y])
        d_all, s_all = self._proj(p, np.arange(len(self.len)))
        window = (self.cum[1:] >= progress - 20.0) & (self.cum[:-1] <= progress + 40.0)
        idx = np.nonzero(window)[0]
        if len(idx):
            d, s = d_all[idx], s_all[idx]
            k = int(np.argmin(d))
            s_here = float(s[k]) if d[k] < 15.0 else progress
        else:
            s_here = progress
        return s_here, float(d_all.min())


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

    def inside(self, lane: str) -> bool:
        if not lane:
            return False
        if lane.startswith(":"):
            a, b = self.net.via_edges.get(lane, ("", ""))
            return a in self.route_edges and b in self.route_edges
        return lane.rsplit("_", 1)[0] in self.route_edges

    def lane_events(self, t: float, pos: float, lane: str, lane_pos: float, st: EgoState,
                    tl_prev: dict[str, str], drivable, size: tuple[float, float]) -> list[Event]:
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
        off = int((~drivable(_corners(st, size))).sum()) >= 2
        if off and not self.roadside:
            ev.append(Event("collision_static", t, pos, "roadside", st.x, st.y))
        self.roadside = off
        # wrong way
        wrong = False
        if lane and lane in net.lane_shape:
            heading = net.lane_pose(lane, lane_pos)[2]
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


def run_episode(scenario: Scenario, instructions: InstructionSet, agent: Agent,
                opts: RunOptions = RunOptions()) -> EpisodeLog:  # noqa: B008
    """Drive one episode and return its log (see :class:`icrsumo.types.EpisodeLog`)."""
    tc = sumo_constants()
    net = load_net(scenario.net)
    m = scenario.manifest
    params = VehicleParams(length=float(m["ego"]["length"]), width=float(m["ego"]["width"]))
    route = _Route(np.asarray(scenario.polyline, dtype=float))
    ego_route = _ego_route(scenario)
    renderer = _renderer(str(scenario.net), opts.bev)
    dt = float(m.get("step_length", 0.05))
    instr = instructions.instructions
    triggers = [i.trigger for i in instr]
    texts = [i.rendered() for i in instr]
    notices = instructions.notices
    sensors = _Sensors(net, set(ego_route.edges))
    controller = WaypointController(params)
    agent.reset(EpisodeInfo(route_id=scenario.route_id, town=scenario.town, net=str(scenario.net),
                            step_length=dt, control_dt=dt * opts.control_every, seed=scenario.seed))
    cols: dict[str, list] = {k: [] for k in ("t", "x", "y", "yaw", "speed", "progress", "instruction",
                                             "outside", "route_dist")}
    events: list[Event] = []
    termination, term_t, message = "sim_error", 0.0, ""
    video = None
    if opts.video is not None:
        from .render import VideoWriter

        video = VideoWriter(opts.video)
    with SumoSession(scenario) as sim:
        ls = sim.ls
        try:
            sim.run_until(scenario.ego_depart)
            sx, sy, sh = scenario.start  # front bumper on the start lane
            state = EgoState(sx - 0.5 * params.length * math.cos(sh),
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
            tls_ids = ls.trafficlight.getIDList()
            for tl in tls_ids:
                ls.trafficlight.subscribe(tl, [tc.TL_RED_YELLOW_GREEN_STATE])
            start_t = sim.time
            monitor = TerminationMonitor(route.total, start_t)
            progress, tl_prev = 0.0, {}
            action = Action(control=Control(brake=1.0))
            n_max = int((route_timeout(route.total) + 10.0) / dt) + 10
            for i in range(n_max):
                t = sim.time
                if EGO_ID not in ls.vehicle.getIDList():
                    ev = [Event("ego_teleport", t, progress, "", state.x, state.y)]
                    events += ev
                    termination, term_t = "stuck", t
                    break
                sub = ls.vehicle.getSubscriptionResults(EGO_ID)
                lane, lane_pos = sub.get(tc.VAR_LANE_ID, ""), float(sub.get(tc.VAR_LANEPOSITION, 0.0))
                ctx = ls.vehicle.getContextSubscriptionResults(EGO_ID) or {}
                veh = [(vid, v) for vid, v in ctx.items() if vid != EGO_ID and tc.VAR_ANGLE in v]
                peds = [v[tc.VAR_POSITION] for vid, v in ctx.items() if tc.VAR_ANGLE not in v]
                vehicles = np.zeros((len(veh), 5))
                for k, (_, v) in enumerate(veh):
                    yaw = math.radians(90.0 - v[tc.VAR_ANGLE])
                    ln = v[tc.VAR_LENGTH]
                    fx, fy = v[tc.VAR_POSITION]
                    vehicles[k] = (fx - 0.5 * ln * math.cos(yaw), fy - 0.5 * ln * math.sin(yaw), yaw, ln,
                                   v[tc.VAR_WIDTH])
                pedestrians = np.array(peds, dtype=float).reshape(-1, 2)
                tl_states = {tl: ls.trafficlight.getSubscriptionResults(tl)[tc.TL_RED_YELLOW_GREEN_STATE]
                             for tl in tls_ids}
                s_here, rdist = route.locate(state.x, state.y, progress)
                progress = max(progress, s_here)
                step_events = []
                colls = ls.simulation.getCollisions()
                if colls:
                    persons = set(ls.person.getIDList())
                    step_events += sensors.collisions(t, progress, state, colls, persons)
                step_events += sensors.lane_events(t, progress, lane, lane_pos, state, tl_prev,
                                                   renderer.drivable_at, (params.length, params.width))
                for vid in ls.simulation.getStartingTeleportIDList():
                    if vid != EGO_ID:
                        step_events.append(Event("teleport_background", t, progress, vid))
                events += step_events
                k_instr = _active(triggers, progress)
                cols["t"].append(t)
                cols["x"].append(state.x)
                cols["y"].append(state.y)
                cols["yaw"].append(state.yaw)
                cols["speed"].append(state.speed)
                cols["progress"].append(progress)
                cols["instruction"].append(instr[k_instr].id if k_instr >= 0 else -1)
                cols["outside"].append(0 if sensors.inside(lane) and not sensors.wrong else 1)
                cols["route_dist"].append(rdist)
                done = monitor.update(t, progress, rdist, state.speed, step_events)
                if done:
                    termination, term_t = done, t
                    break
                if i % opts.control_every == 0:
                    notice = ""
                    for n in notices:
                        if n.trigger <= progress < n.end:
                            notice = n.text
                    bev = renderer.render((state.x, state.y, state.yaw), (params.length, params.width),
                                          vehicles, pedestrians, tl_states)
                    world = None
                    if getattr(agent, "privileged", False):
                        world = World(net=net, ego=state, lane=lane, lane_pos=lane_pos, vehicles=vehicles,
                                      pedestrians=pedestrians, tl_states=tl_states, route=ego_route,
                                      progress=progress)
                    obs = Observation(t=t, bev=bev, speed=state.speed,
                                      instruction=texts[k_instr] if k_instr >= 0 else "",
                                      instruction_id=instr[k_instr].id if k_instr >= 0 else -1,
                                      notice=notice, world=world)
                    action = validate_action(agent.act(obs))
                    if video is not None:
                        video.add(bev, obs.instruction, notice, state.speed)
                control = action.control if action.control is not None else controller.control(
                    np.asarray(action.waypoints, dtype=float), state.speed, dt, action.target_speed)
                state = step(state, control, dt, params)
                fx, fy = state.front(params.length)
                ls.vehicle.moveToXY(EGO_ID, "", -1, fx, fy, 90.0 - math.degrees(state.yaw), 2)
                tl_prev = tl_states
                ls.simulationStep()
            else:
                termination, term_t = "route_timeout", sim.time
        except Exception as err:  # libsumo raises TraCIException and friends
            if type(err).__module__.startswith("libsumo") or "TraCI" in type(err).__name__:
                termination, term_t, message = "sim_error", sim.time, f"{type(err).__name__}: {err}"
                events.append(Event("sim_error", term_t, 0.0, message))
            else:
                raise
        finally:
            if video is not None:
                video.close()
    return EpisodeLog(
        route_id=scenario.route_id, agent=getattr(agent, "name", type(agent).__name__),
        family=instructions.family, k=instructions.k, seed=scenario.seed, step_length=dt,
        route_length=route.total, t=tuple(cols["t"]), x=tuple(cols["x"]), y=tuple(cols["y"]),
        yaw=tuple(cols["yaw"]), speed=tuple(cols["speed"]), progress=tuple(cols["progress"]),
        instruction=tuple(cols["instruction"]), outside=tuple(cols["outside"]),
        route_dist=tuple(cols["route_dist"]), events=tuple(events), termination=termination,
        termination_t=term_t, message=message,
    )
