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


class Hangs(Cruise):
    """Stops answering on its third decision (sleeps for an hour)."""

    name = "hangs"

    def reset(self, info: EpisodeInfo) -> None:
        self.n = 0

    def act(self, obs: Observation) -> Action:
        import time

        self.n += 1
        if self.n == 3:
            time.sleep(3600)
        return super().act(obs)


class NonDeterministic(Cruise):
    """Draws its speed from numpy's global random state: differs between runs with the same seed."""

    name = "non-deterministic"

    def act(self, obs: Observation) -> Action:
        speed = float(np.random.uniform(3, 6))  # noqa: NPY002 - the bug this agent demonstrates
        return Action(waypoints=np.array([[2.5, 0.0], [5.0, 0.0]]), target_speed=speed)


class NoName:
    """Implements reset and act but declares neither name nor privileged."""

    def reset(self, info: EpisodeInfo) -> None:
        pass

    def act(self, obs: Observation) -> Action:
        return Action(waypoints=np.array([[2.5, 0.0], [5.0, 0.0]]), target_speed=4.0)


class ReturnsDict(Cruise):
    """Returns a dict instead of an Action."""

    name = "returns-dict"

    def act(self, obs: Observation) -> Action:
        return {"steer": 0.0, "throttle": 0.5}  # type: ignore[return-value]


class Slow(Cruise):
    """Takes 0.15 s per decision."""

    name = "slow"

    def act(self, obs: Observation) -> Action:
        import time

        time.sleep(0.15)
        return super().act(obs)


class BevKeeper:
    """A deterministic, non-privileged agent that uses everything it sees: it steers towards the
    middle of the drivable area 6-12 m ahead in the BEV raster, stops for vehicles and red stop
    lines in its corridor, and sets its speed from the instruction and notice. ``act`` is a pure
    function of the observation, so it also offers the ``act_batch`` hook."""

    name = "bev-keeper"
    privileged = False

    def reset(self, info: EpisodeInfo) -> None:
        self.dt = info.control_dt

    def act(self, obs: Observation) -> Action:
        return self.plan(obs)

    def act_batch(self, observations: list[Observation]) -> list[Action]:
        return [self.plan(o) for o in observations]

    @staticmethod
    def plan(obs: Observation) -> Action:
        bev = obs.bev
        row_ego, col_ego, m_per_px = 96, 64, 0.5
        ahead = 6.0 + 0.5 * min(obs.speed, 12.0)
        row = int(row_ego - ahead / m_per_px)
        drivable = np.nonzero(bev[0, row] > 0)[0]
        left = 0.0
        if len(drivable):
            near = drivable[np.abs(drivable - col_ego) <= 12]
            if len(near):
                left = float(col_ego - near.mean()) * m_per_px
        corridor = bev[:, row:row_ego - 6, col_ego - 5:col_ego + 6]
        blocked = bool(corridor[2].any() or corridor[5].any())
        speed = 0.0 if blocked else 4.0 + 0.25 * (len(obs.instruction) % 5) - (1.0 if obs.notice else 0.0)
        xs = np.array([0.25, 0.5, 0.75, 1.0]) * ahead
        return Action(waypoints=np.stack([xs, xs / ahead * left], axis=1), target_speed=speed)


class Dies(Cruise):
    """Kills its own process on the first decision (as a segfault in native code would)."""

    name = "dies"

    def act(self, obs: Observation) -> Action:
        import os

        os._exit(3)


class Exits(Cruise):
    """Calls ``sys.exit`` on its second decision (as a careless script would)."""

    name = "exits"

    def act(self, obs: Observation) -> Action:
        import sys

        self.n = getattr(self, "n", 0) + 1
        if self.n == 2:
            sys.exit(0)
        return super().act(obs)


class Interrupts(Cruise):
    """Raises ``KeyboardInterrupt`` itself on its second decision."""

    name = "interrupts"

    def act(self, obs: Observation) -> Action:
        self.n = getattr(self, "n", 0) + 1
        if self.n == 2:
            raise KeyboardInterrupt
        return super().act(obs)


class Flaky(Cruise):
    """Crashes while a file ``flaky.marker`` exists in the working folder (a transient fault)."""

    name = "flaky"

    def act(self, obs: Observation) -> Action:
        from pathlib import Path

        if Path("flaky.marker").exists():
            raise ConnectionError("the service it needs is down")
        return super().act(obs)


class Boom(BaseException):
    """Not an Exception: what careless agent code may raise."""


class RaisesBase(Cruise):
    """Raises a BaseException of its own on its second decision."""

    name = "raises-base"

    def act(self, obs: Observation) -> Action:
        self.n = getattr(self, "n", 0) + 1
        if self.n == 2:
            raise Boom("not an Exception")
        return super().act(obs)
