"""The simulator backend: the only module of the package that imports libsumo.

:class:`SumoSession` is a context-managed, in-process SUMO run of a scenario; libsumo runs one
simulation per process, so a session must be closed (the context manager always does, also on
error) before the next one starts. :class:`SumoBackend` is what the closed loop uses: start the
scenario, insert the ego, place it at a pose, step, and :meth:`SumoBackend.read` SUMO's state
as a frozen :class:`~icrsumo.sim.frame.SimFrame`. Every libsumo error surfaces as a
:class:`SimulatorError` whose ``message`` is ``"TraCIException: ..."``.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Sequence

import numpy as np

from icrsumo.core.resources import sumo_home
from icrsumo.world.scenario import Scenario

from .frame import NO_LIGHTS, Contact, SimFrame
from .match import FULL_RADIUS

EGO_ID = "ego"
#: radius (m) of the context subscription around the ego (nearby vehicles and persons)
CONTEXT_RADIUS = 60.0
#: how far (m) SUMO looks for lanes when the ego is moved (``moveToXY``'s ``matchThreshold``):
#: SUMO's default, which defines the episodes. A uniformly narrower search is cheaper but not the
#: same: SUMO normalises the distance term of its lane ranking by the largest distance in range
#: (capped at a lane width), so where no other lane lies within the narrower radius the choice
#: between the near lanes changes (50 m changed 3 of 18 perturbed training drives,
#: docs/performance.md). ``SumoBackend(search=...)`` narrows it only where that provably picks
#: the same lane (:mod:`icrsumo.sim.match`).
MATCH_RADIUS_M = FULL_RADIUS

_active = False  # libsumo's own state is per process: at most one session is open


def _libsumo():
    sumo_home()  # sets SUMO_HOME before libsumo looks for it
    import libsumo

    return libsumo


def sumo_constants():
    """libsumo's constants module (variable ids for subscriptions)."""
    return _libsumo().constants


class SimulatorError(RuntimeError):
    """SUMO failed (libsumo raised); ``message`` is ``"<libsumo error type>: <its text>"``."""

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message


def _is_libsumo_error(err: BaseException) -> bool:
    return type(err).__module__.startswith("libsumo") or "TraCI" in type(err).__name__


@contextlib.contextmanager
def _translated():
    """Turn libsumo's exceptions into :class:`SimulatorError`; others pass unchanged."""
    try:
        yield
    except SimulatorError:
        raise
    except Exception as err:
        if _is_libsumo_error(err):
            raise SimulatorError(f"{type(err).__name__}: {err}") from err
        raise


def add_ego(ls, scenario: Scenario) -> None:
    """Add the ego to a running simulation ``ls`` now: on ``ego_route`` at the scenario's start
    lane and position, standing (SUMO inserts it when the spot is free)."""
    lane_index = scenario.start_lane.rsplit("_", 1)[1]
    ls.vehicle.add(EGO_ID, "ego_route", typeID="ego", depart="now", departLane=lane_index,
                   departPos=f"{scenario.start_pos:.2f}", departSpeed="0")


#: m/s^2 a background car is assumed to brake with when the ego appears in front of it
START_BRAKE = 4.5
#: s a background car takes to react to the ego appearing in front of it
START_REACTION = 1.0


def clear_start(ls, x: float, y: float, yaw: float, scenario: Scenario) -> list[str]:
    """Remove the background vehicles that could not stop for the ego appearing at its start
    (front bumper at (x, y) m heading ``yaw`` rad): those in its lane's corridor (1.8 m either
    side, heading within 60 degrees of it) whose front is behind the ego's rear by less than
    their stopping distance (``START_REACTION`` s, then ``START_BRAKE`` m/s^2, + 2 m) or that
    overlap its footprint. Without this a car arriving at 13 m/s rear-ends the standing ego
    half a second into the episode. Returns the removed ids (sorted)."""
    length = scenario.ego.length
    c, s = math.cos(yaw), math.sin(yaw)
    gone = []
    for vid in sorted(ls.vehicle.getIDList()):
        if vid == EGO_ID:
            continue
        vx, vy = ls.vehicle.getPosition(vid)            # its front bumper
        lon, lat = (vx - x) * c + (vy - y) * s, -(vx - x) * s + (vy - y) * c
        heading = math.radians(90.0 - ls.vehicle.getAngle(vid))
        if abs(lat) > 1.8 or abs((heading - yaw + math.pi) % (2 * math.pi) - math.pi) > math.pi / 3:
            continue
        v = ls.vehicle.getSpeed(vid)
        behind = -length - lon                          # its front to the ego's rear, m
        stopping = v * START_REACTION + v * v / (2 * START_BRAKE) + 2.0
        if behind < stopping and lon - ls.vehicle.getLength(vid) < 1.0:
            ls.vehicle.remove(vid)
            gone.append(vid)
    return gone


def remove_background_collisions(ls, colls) -> tuple[str, ...]:
    """Remove the background vehicles that collided in the last step (``colls``, SUMO's
    collision records of that step) with another background
    vehicle or a pedestrian (never the ego, never a pedestrian). The scenarios keep SUMO's
    ``collision.action warn`` so that the ego's contacts are recorded and it drives on; two
    background cars that touch inside a junction (SUMO's junction model lets foes in now and
    then) would otherwise stand interlocked for good, a wall no driver could pass. SUMO's own
    ``teleport`` action does the same to both parties. Returns the removed ids (sorted)."""
    if not colls:
        return ()
    gone = set()
    persons = None
    for c in colls:
        if EGO_ID in (c.collider, c.victim):
            continue
        if persons is None:
            persons = set(ls.person.getIDList())
        gone.update(v for v in (c.collider, c.victim) if v not in persons)
    present = set(ls.vehicle.getIDList()) if gone else set()
    removed = tuple(sorted(v for v in gone if v in present))
    for v in removed:
        ls.vehicle.remove(v)
    return removed


class SumoSession:
    """One SUMO run of a scenario: ``with SumoSession(sc) as s: s.step()``.

    Time is in s; the step length comes from the scenario's ``.sumocfg``.
    """

    def __init__(self, scenario: Scenario, extra_args: tuple[str, ...] = ()) -> None:
        self.scenario = scenario
        self.extra_args = tuple(extra_args)
        self.ls = None

    def __enter__(self) -> SumoSession:
        global _active
        if _active:
            raise RuntimeError("libsumo runs one simulation per process; close the other first")
        ls = _libsumo()
        ls.start(["sumo", "-c", str(self.scenario.sumocfg), "--seed", str(self.scenario.seed),
                  "--no-step-log", "true", *self.extra_args])
        _active = True
        self.ls = ls
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        global _active
        if self.ls is not None:
            try:
                self.ls.close()
            finally:
                self.ls = None
                _active = False

    @property
    def time(self) -> float:
        """Current simulation time (s)."""
        return float(self.ls.simulation.getTime())

    def step(self, n: int = 1) -> None:
        """Advance ``n`` simulation steps."""
        for _ in range(n):
            self.ls.simulationStep()

    def run_until(self, t: float) -> None:
        """Step until the simulation time reaches ``t`` (s)."""
        dt = float(self.ls.simulation.getDeltaT())
        while self.time + 1e-9 < t:
            self.ls.simulationStep()
            if dt <= 0:
                break

    def insert_ego(self, max_wait: float = 30.0) -> bool:
        """Insert the ego at its start lane position on ``ego_route`` at the current time and
        step until SUMO has placed it (insertion waits while the spot is occupied, at most
        ``max_wait`` s). Returns whether the ego is in the simulation."""
        add_ego(self.ls, self.scenario)
        deadline = self.time + max_wait
        while self.time < deadline:
            self.ls.simulationStep()
            if EGO_ID in self.ls.vehicle.getIDList():
                return True
        return False

    def ego_state(self) -> dict:
        """Ego road id, lane id, lane position (m), x, y (m, front bumper), speed (m/s)."""
        v = self.ls.vehicle
        x, y = v.getPosition(EGO_ID)
        return {"road": v.getRoadID(EGO_ID), "lane": v.getLaneID(EGO_ID),
                "pos": v.getLanePosition(EGO_ID), "x": x, "y": y, "speed": v.getSpeed(EGO_ID),
                "route": tuple(v.getRoute(EGO_ID))}


class SumoBackend:
    """The closed loop's view of SUMO for one scenario (see the module docstring).

    ``start()`` starts SUMO, ``run_until(t)`` runs the traffic warm-up up to the ego's departure;
    ``insert_ego(x, y, yaw)`` adds the externally driven ego at the scenario's start (pose of
    its front bumper, m and rad) and takes one step; ``place_ego(x, y, yaw)`` moves it there
    for the next ``step()``, SUMO searching lanes within ``search(x, y)`` m (None: always
    ``MATCH_RADIUS_M``; :meth:`icrsumo.sim.match.MatchGrid.radius` gives the same lanes
    faster); ``read(surroundings)`` returns the :class:`SimFrame` of the current step (the
    nearby actors only when ``surroundings``). ``close()`` is idempotent.
    """

    def __init__(self, scenario: Scenario, context_radius: float = CONTEXT_RADIUS,
                 search: Callable[[float, float], float] | None = None) -> None:
        self.scenario = scenario
        self.context_radius = context_radius
        self.search = search
        self._session: SumoSession | None = None
        self.tls_ids: tuple[str, ...] = ()
        self._removed: tuple[str, ...] = ()   # background vehicles removed in the last step
        self._colls: tuple = ()                # SUMO's collision records of the last step

    def __enter__(self) -> SumoBackend:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self._session is not None:
            session, self._session = self._session, None
            session.close()

    @property
    def session(self) -> SumoSession | None:
        """The underlying session (None before ``start()`` and after ``close()``): raw libsumo
        for measurements (``tools/benchmark.py``)."""
        return self._session

    @property
    def time(self) -> float:
        """Current simulation time (s)."""
        with _translated():
            return self._session.time

    def start(self) -> None:
        """Start SUMO on the scenario (its config and seed)."""
        with _translated():
            self._session = SumoSession(self.scenario).__enter__()
            self._tc = tc = sumo_constants()
            self._lane_var, self._pos_var = tc.VAR_LANE_ID, tc.VAR_LANEPOSITION
            self._tl_var = tc.TL_RED_YELLOW_GREEN_STATE

    def run_until(self, t: float) -> None:
        """Step the traffic until simulation time ``t`` (s): the warm-up before the ego departs."""
        with _translated():
            self._session.run_until(t)

    def insert_ego(self, x: float, y: float, yaw: float) -> None:
        """Add the ego on the scenario's start lane, place its front bumper at (x, y) m heading
        ``yaw`` rad, take one step and subscribe to what :meth:`read` needs."""
        tc = self._tc
        with _translated():
            ls = self._session.ls
            clear_start(ls, x, y, yaw, self.scenario)
            add_ego(ls, self.scenario)
            ls.vehicle.setSpeedMode(EGO_ID, 0)
            ls.vehicle.setLaneChangeMode(EGO_ID, 0)
            ls.vehicle.moveToXY(EGO_ID, "", -1, x, y, 90.0 - math.degrees(yaw), 2, MATCH_RADIUS_M)
            ls.simulationStep()
            self._colls = ls.simulation.getCollisions()
            ls.vehicle.subscribe(EGO_ID, [tc.VAR_LANE_ID, tc.VAR_LANEPOSITION])
            ls.vehicle.subscribeContext(EGO_ID, tc.CMD_GET_VEHICLE_VARIABLE, self.context_radius,
                                        [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_LENGTH, tc.VAR_WIDTH])
            ls.vehicle.subscribeContext(EGO_ID, tc.CMD_GET_PERSON_VARIABLE, self.context_radius,
                                        [tc.VAR_POSITION])
            self.tls_ids = tuple(ls.trafficlight.getIDList())
            for tl in self.tls_ids:
                ls.trafficlight.subscribe(tl, [tc.TL_RED_YELLOW_GREEN_STATE])

    def place_ego(self, x: float, y: float, yaw: float) -> None:
        """Move the ego's front bumper to (x, y) m heading ``yaw`` rad (SUMO keeps it on the
        nearest lane, or off every lane when none is near: ``keepRoute=2``)."""
        radius = MATCH_RADIUS_M if self.search is None else self.search(x, y)
        with _translated():
            self._session.ls.vehicle.moveToXY(EGO_ID, "", -1, x, y, 90.0 - math.degrees(yaw), 2,
                                              radius)

    def step(self) -> None:
        """One SUMO step; background vehicles that collided with each other in it are removed
        (:func:`remove_background_collisions`) and reported by the next :meth:`read` as
        teleports."""
        with _translated():
            ls = self._session.ls
            ls.simulationStep()
            self._colls = ls.simulation.getCollisions()
            self._removed = remove_background_collisions(ls, self._colls)

    def read(self, surroundings: bool = False,
             lights: Callable[[str], Sequence[str]] | None = None) -> SimFrame:
        """SUMO's state at the current step (see :class:`SimFrame`): with the surroundings (nearby
        actors and every light's state) when ``surroundings``; otherwise the states of every
        light, or, given ``lights`` (the ego's lane -> light ids), of those lights only."""
        with _translated():
            ls = self._session.ls
            t = float(ls.simulation.getTime())
            sub = ls.vehicle.getSubscriptionResults(EGO_ID)
            # results exist only while the ego does (after a moveToXY it is also in getIDList())
            if not sub and EGO_ID not in ls.vehicle.getIDList():
                return SimFrame(t=t, ego_present=False)
            contacts = ()
            colls = self._colls
            if colls:
                persons = set(ls.person.getIDList())
                found = []
                for c in colls:
                    if c.collider == EGO_ID:
                        other = c.victim
                    elif c.victim == EGO_ID:
                        other = c.collider
                    else:
                        continue
                    found.append(Contact(other, other in persons))
                contacts = tuple(found)
            teleports = ls.simulation.getStartingTeleportIDList()
            teleports = tuple(v for v in teleports if v != EGO_ID) if teleports else ()
            if self._removed:
                teleports += self._removed
            lane, tl_var = sub.get(self._lane_var, ""), self._tl_var
            if surroundings or lights is None:
                tl_all = ls.trafficlight.getAllSubscriptionResults()
                tl_states = {tl: tl_all[tl][tl_var] for tl in self.tls_ids}
            else:
                wanted = lights(lane)
                get = ls.trafficlight.getSubscriptionResults
                tl_states = {tl: get(tl)[tl_var] for tl in wanted} if wanted else NO_LIGHTS
            vehicles = pedestrians = None
            if surroundings:
                vehicles, pedestrians = self._surroundings(ls)
            speeds = [ls.vehicle.getSpeed(v) for v in ls.vehicle.getIDList() if v != EGO_ID]
            return SimFrame(t=t, ego_present=True, lane=lane,
                            lane_pos=float(sub.get(self._pos_var, 0.0)), contacts=contacts,
                            any_collision=bool(colls),
                            teleports=teleports, tl_states=tl_states, vehicles=vehicles,
                            pedestrians=pedestrians,
                            traffic_speed=math.fsum(speeds) / len(speeds) if speeds else -1.0)

    def _surroundings(self, ls) -> tuple[np.ndarray, np.ndarray]:
        """Vehicles (N, 5: centre x, y, yaw, length, width) and pedestrians (M, 2) within the
        context radius (SUMO reports a vehicle's front bumper: it is moved to the centre)."""
        tc = self._tc
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
        return np.array(rows, dtype=float).reshape(-1, 2 + 3), np.array(peds, dtype=float).reshape(-1, 2)
