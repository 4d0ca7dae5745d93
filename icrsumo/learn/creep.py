"""Creeping out of a standstill: what a learned agent does when its network will not start again
(issue 47).

A network that reads its own speed learns that a car standing still mostly stays still (the
inertia problem of behaviour cloning): the shipped agents stopped at the all-way stop signs of
the bundled tiny suite and never drove on (72 of the default ICR run's 528 episodes ran to the
route's time-out), and on CARLA's towns they stood for good at empty junctions and green lights
(7 of `carla-fidelity`'s 104 baselines ended blocked). Their stop output there does not depend on
the stopped time they read, nor on the text. :class:`Creep` watches, from the agent's own
observation, for such a standstill and then overrides the stop decision for a short while, as
learned CARLA agents do ("creeping"), so that the network reads a moving ego again and drives
on. It creeps only where the raster shows nothing to wait for:

* the ego has stood (speed below :data:`STILL_SPEED`) for :data:`AFTER_S` seconds and the
  network still asks to stop;
* no vehicle or pedestrian anywhere in the raster ahead of the ego's front within
  :data:`SIDE_M` to either side (the whole view ahead: the creep never moves towards a road user
  it can see);
* no stop line in the ego's lane within :data:`LINE_M` ahead (a red light) — unless the active
  notice or instruction names a stop sign (:data:`SIGN`) and no green line ('go' pixel) was seen
  anywhere in the raster while standing: a stop sign's line is drawn like a red light's, and a
  light shows green somewhere in a cycle while a stop sign never does.

Creeping lasts :data:`CREEP_S` seconds at a target speed of at least :data:`CREEP_SPEED` along
the network's own waypoints, and ends at once when a road user comes into view ahead. The
raster is read in the layout the shipped networks are trained on (the default
:class:`icrsumo.render.BevSpec`, :data:`M_PER_PX`; the ego is found by its own channel).
The rule is drawn from traces of the tiny suite, `carla-fidelity` and LangAuto
(docs/learned-agents.md measures it, docs/fidelity.md per route).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from icrsumo.agents.base import Action, Observation

#: raster resolution (m per pixel) of the networks' BEV (the default BevSpec)
M_PER_PX = 0.5
#: channel indices in the raster (icrsumo.render.CHANNELS; a test keeps them equal)
VEHICLES, PEDESTRIANS, EGO, STOP, GO = 2, 3, 4, 5, 6
#: the ego stands when its speed (m/s) is below this
STILL_SPEED = 0.1
#: stood this long (s) with the network asking to stop: creep
AFTER_S = 10.0
#: a creep lasts this long (s) ...
CREEP_S = 3.0
#: ... at a target speed (m/s) of at least this
CREEP_SPEED = 2.5
#: the network "asks to stop" when its target speed (m/s) is below this
STOP_TARGET = 0.5
#: road users within this distance (m) to either side of the ego, anywhere ahead, hold the creep
SIDE_M = 16.0
#: a stop line in the ego's lane (its width ± LANE_HALF_M) this far ahead (m) is a red light ...
LINE_M = 15.0
LANE_HALF_M = 1.5
#: ... unless the notice or the instruction names a stop sign
SIGN = re.compile(r"\bstop sign\b|\bthe sign\b", re.IGNORECASE)


def _ego(bev: np.ndarray) -> tuple[int, int] | None:
    """(front row, centre column) of the ego in raster ``bev`` (C, H, W); None without an ego."""
    rows = np.flatnonzero(bev[EGO].any(axis=1))
    cols = np.flatnonzero(bev[EGO].any(axis=0))
    if not len(rows):
        return None
    return int(rows[0]), int(round((cols[0] + cols[-1]) / 2.0))


def road_user_ahead(bev: np.ndarray, ego: tuple[int, int] | None = None) -> bool:
    """Whether a vehicle or pedestrian shows anywhere ahead of the ego's front, within
    :data:`SIDE_M` to either side (True without an ego in the raster); ``ego``: :func:`_ego`'s
    answer when the caller has it."""
    ego = ego or _ego(bev)
    if ego is None:
        return True
    front, col = ego
    side = int(round(SIDE_M / M_PER_PX))
    return bool(bev[VEHICLES:PEDESTRIANS + 1, :front, max(col - side, 0):col + side + 1].any())


def red_line_ahead(bev: np.ndarray, ego: tuple[int, int] | None = None) -> bool:
    """Whether a stop line shows in the ego's lane within :data:`LINE_M` ahead of its front
    (from 1 m behind the front: a line the bumper is on); ``ego`` as :func:`road_user_ahead`."""
    ego = ego or _ego(bev)
    if ego is None:
        return False
    front, col = ego
    ahead, half = int(round(LINE_M / M_PER_PX)), int(round(LANE_HALF_M / M_PER_PX))
    back = int(round(1.0 / M_PER_PX))
    return bool(bev[STOP, max(front - ahead, 0):front + back, max(col - half, 0):col + half + 1].any())


@dataclass
class Creep:
    """One episode's standstill watch (mutable; one per agent and episode). :meth:`action` is
    called once per control step with the observation and the network's action and returns the
    action to take."""

    still_since: float | None = None   # s: when the ego came to a stand (None: moving)
    green_seen: bool = False           # a 'go' pixel in the raster since then
    until: float = -1.0                # s: a creep under way ends here
    creeps: int = 0                    # creeps started this episode

    def clear(self, obs: Observation) -> bool:
        """Whether the raster shows nothing to wait for (module docstring)."""
        ego = _ego(obs.bev)
        if road_user_ahead(obs.bev, ego):
            return False
        if red_line_ahead(obs.bev, ego):
            sign = bool(SIGN.search(obs.notice) or SIGN.search(obs.instruction))
            return sign and not self.green_seen
        return True

    def action(self, obs: Observation, act: Action) -> Action:
        t = obs.t
        if obs.speed >= STILL_SPEED:
            self.still_since = None
        elif self.still_since is None:
            self.still_since, self.green_seen = t, False
        if self.still_since is not None and not self.green_seen:
            self.green_seen = bool(obs.bev[GO].any())
        target = act.target_speed or 0.0
        if t < self.until:
            if self.clear(obs):
                return _creeping(act, target)
            self.until = -1.0
        if self.still_since is not None and t - self.still_since >= AFTER_S and target < STOP_TARGET \
                and self.clear(obs):
            self.until, self.still_since = t + CREEP_S, None
            self.creeps += 1
            return _creeping(act, target)
        return act


def _creeping(act: Action, target: float) -> Action:
    """The network's action with its target speed raised to at least :data:`CREEP_SPEED`."""
    return Action(waypoints=act.waypoints, target_speed=max(target, CREEP_SPEED))
