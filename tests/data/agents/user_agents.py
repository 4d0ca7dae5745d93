"""Users' agents for tests: a minimal working agent and broken ones (real classes, loaded by path)."""

from __future__ import annotations

import numpy as np

from icrsumo.agents.base import Action, EpisodeInfo, Observation


class Cruise:
    """Drives straight ahead at 5 m/s whatever it is told (a complete minimal agent)."""

    name = "cruise"
    privileged = False

    def reset(self, info: EpisodeInfo) -> None:
        self.dt = info.control_dt

    def act(self, obs: Observation) -> Action:
        return Action(waypoints=np.array([[2.5, 0.0], [5.0, 0.0], [7.5, 0.0]]), target_speed=5.0)


class Raises:
    """Raises on its third decision."""

    name = "raises"
    privileged = False

    def reset(self, info: EpisodeInfo) -> None:
        self.n = 0

    def act(self, obs: Observation) -> Action:
        self.n += 1
        if self.n == 3:
            raise RuntimeError("agent exploded")
        return Action(waypoints=np.array([[2.0, 0.0], [4.0, 0.0]]), target_speed=3.0)


class NoAct:
    """Does not implement the protocol."""

    def reset(self, info: EpisodeInfo) -> None:
        pass


class NaNs(Cruise):
    """Returns NaN waypoints."""

    name = "nans"

    def act(self, obs: Observation) -> Action:
        return Action(waypoints=np.array([[np.nan, 0.0], [5.0, 0.0]]))


class WrongShape(Cruise):
    """Returns a flat waypoint vector."""

    name = "wrong-shape"

    def act(self, obs: Observation) -> Action:
        return Action(waypoints=np.array([2.5, 5.0, 7.5]))
