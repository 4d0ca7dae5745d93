"""The only module that imports libsumo: a context-managed, in-process SUMO session.

libsumo runs one simulation per process; a session must be closed (the context manager always
does, also on error) before the next one starts.
"""

from __future__ import annotations

from .resources import sumo_home
from .scenario import Scenario

EGO_ID = "ego"

_active = False


def _libsumo():
    sumo_home()  # sets SUMO_HOME before libsumo looks for it
    import libsumo

    return libsumo


def sumo_constants():
    """libsumo's constants module (variable ids for subscriptions)."""
    return _libsumo().constants


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
        sc = self.scenario
        lane_index = sc.start_lane.rsplit("_", 1)[1]
        self.ls.vehicle.add(
            EGO_ID, "ego_route", typeID="ego", depart="now", departLane=lane_index,
            departPos=f"{sc.start_pos:.2f}", departSpeed="0",
        )
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
