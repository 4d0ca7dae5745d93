"""Deprecated: moved to :mod:`icrsumo.scoring` (the route criteria monitor in
:mod:`icrsumo.scoring.criteria`, whose ``rules`` argument is now required; the dense route in
:mod:`icrsumo.scoring.route`; each rule set's ``RouteRules`` in its module); re-exported here.
"""

from __future__ import annotations

from icrsumo.scoring.criteria import (
    BLOCKED_S,
    BLOCKED_SPEED,
    DEVIATION_M,
    ENDING_EVENTS,
    EPS,
    MIN_TIMEOUT_LB2,
    OFF_LANES,
    OFF_LANES_LB2,
    WRONG_LANE,
    WRONG_LANE_LB2,
    RouteRules,
    TerminationMonitor,
    events_by_step,
    replay,
    route_timeout,
    run_monitor,
)
from icrsumo.scoring.lb1 import LB1_RULES
from icrsumo.scoring.lb2 import LB2_RULES
from icrsumo.scoring.route import HOP_M, DenseRoute, angle_diff, dense_route

#: scoring name -> its route criteria (now each rule set's ``rules``: icrsumo.scoring.get_scoring(name).rules)
ROUTE_RULES = {r.name: r for r in (LB1_RULES, LB2_RULES)}

__all__ = ["BLOCKED_S", "BLOCKED_SPEED", "DEVIATION_M", "ENDING_EVENTS", "EPS", "HOP_M", "LB1_RULES",
           "LB2_RULES", "MIN_TIMEOUT_LB2", "OFF_LANES", "OFF_LANES_LB2", "ROUTE_RULES", "WRONG_LANE",
           "WRONG_LANE_LB2",
           "DenseRoute", "RouteRules", "TerminationMonitor", "angle_diff", "dense_route", "events_by_step",
           "replay", "route_timeout", "run_monitor"]
