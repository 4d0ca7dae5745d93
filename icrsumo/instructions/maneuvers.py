"""Maneuvers from route geometry: what the route asks of the driver, and where (m along it).

Input is a converted scenario (its route's junction passes and lane changes,
:class:`~icrsumo.core.types.JunctionPass`, :class:`~icrsumo.core.types.LaneChange`) and its network.
Junction kinds follow LangAuto's qualifiers: traffic_light, stop_sign, t_junction, crossroad,
roundabout (with exit number), highway_entry / highway_exit.
"""

from __future__ import annotations

from collections.abc import Sequence

from icrsumo.core.types import Intent, JunctionPass, Maneuver
from icrsumo.world.networks import RoadNet
from icrsumo.world.scenario import Scenario

#: an edge with a speed limit at or above this (m/s, 90 km/h) is highway
HIGHWAY_SPEED = 25.0
#: room (m) a lane change needs per lane crossed before the junction where the lane matters
LANE_CHANGE_ROOM_M = 30.0
#: room (m) left after a lane change moved back for the following junction's announcement
ANNOUNCE_ROOM_M = 50.0

_TURN = {"s": ("straight", Intent.STRAIGHT), "l": ("turn_left", Intent.LEFT),
         "L": ("turn_left", Intent.LEFT), "r": ("turn_right", Intent.RIGHT),
         "R": ("turn_right", Intent.RIGHT), "t": ("u_turn", Intent.UNKNOWN)}


def roundabout_intent(exit_number: int) -> Intent:
    """LangAuto-style reading of a roundabout exit on a four-arm roundabout:
    1st exit = right, 2nd = straight, 3rd or later = left."""
    return {1: Intent.RIGHT, 2: Intent.STRAIGHT}.get(exit_number, Intent.LEFT)


def junction_kind(net: RoadNet, node: str) -> str:
    """traffic_light, stop_sign, t_junction, crossroad or junction for a SUMO node."""
    ntype = net.node_type.get(node, "")
    if ntype.startswith("traffic_light"):
        return "traffic_light"
    if ntype in ("priority_stop", "allway_stop"):
        return "stop_sign"
    arms = net.node_arms(node)
    if arms == 3:
        return "t_junction"
    if arms >= 4:
        return "crossroad"
    return "junction"


def is_highway(net: RoadNet, edge: str) -> bool:
    return net.edge_speed.get(edge, 0.0) >= HIGHWAY_SPEED


def junction_exit(net: RoadNet, j: JunctionPass) -> float:
    """Route position (m) where the ego leaves junction pass ``j``: its entry ``pos`` plus the
    length of the internal lanes of the connection it uses."""
    conns = net.connections.get((j.from_edge, j.to_edge), ())
    via = next((c.via_length for c in conns if c.from_lane == j.from_lane and c.to_lane == j.to_lane),
               max((c.via_length for c in conns), default=0.0))
    return round(j.pos + via, 2)


def lane_change_pos(pos: float, lanes: int, junctions: Sequence[JunctionPass],
                    turns: list[Maneuver]) -> float:
    """Route position (m) where a lane change across ``lanes`` lanes is asked for. The route
    builder puts it at the start of the edge whose exit needs the other lane; where that edge
    is too short to change on (under ``LANE_CHANGE_ROOM_M`` per lane before its junction, e.g. a
    few metres between two junctions of a CARLA town), the change is asked for earlier, with
    room for it and for the turn's announcement after it, but not before the previous junction
    maneuver's exit."""
    ahead = next((j.pos for j in junctions if j.pos >= pos), None)
    if ahead is None or ahead - pos >= LANE_CHANGE_ROOM_M * lanes:
        return pos
    floor = max((float(m.end) for m in turns if m.end <= pos + 1e-6), default=0.0)
    return round(max(floor, min(pos, ahead - LANE_CHANGE_ROOM_M * lanes - ANNOUNCE_ROOM_M)), 2)


def extract_maneuvers(scenario: Scenario, net: RoadNet) -> list[Maneuver]:
    """Junction maneuvers (where the route has a choice, or enters / leaves a highway) and the
    lane changes it requires, sorted by route position. Follow stretches are the gaps between
    them and are added by the instruction generator."""
    junctions = scenario.route.junctions
    out: list[Maneuver] = []
    i = 0
    while i < len(junctions):
        j = junctions[i]
        ring = net.roundabout_edges
        if net.enters_roundabout(j.from_edge, j.to_edge):
            # entering a roundabout: count the exits passed up to the one taken
            exit_no, k = 0, i + 1
            while k < len(junctions) and junctions[k].from_edge in ring:
                jk = junctions[k]
                if any(s not in ring for s in net.successors.get(jk.from_edge, ())):
                    exit_no += 1
                if jk.to_edge not in ring:
                    break
                k += 1
            exit_no = max(exit_no, 1)
            last = junctions[min(k, len(junctions) - 1)]
            out.append(Maneuver("roundabout", j.pos, roundabout_intent(exit_no), "roundabout",
                                j.junction, exit=exit_no, end=junction_exit(net, last)))
            i = k + 1
            continue
        from_hw, to_hw = is_highway(net, j.from_edge), is_highway(net, j.to_edge)
        if to_hw and not from_hw:
            out.append(Maneuver("highway_enter", j.pos, Intent.FOLLOW, "highway_entry",
                                j.junction, end=junction_exit(net, j)))
        elif from_hw and not to_hw and j.choice:
            out.append(Maneuver("highway_exit", j.pos, Intent.RIGHT, "highway_exit",
                                j.junction, end=junction_exit(net, j)))
        elif j.choice:
            kind, intent = _TURN.get(j.direction, ("straight", Intent.STRAIGHT))
            out.append(Maneuver(kind, j.pos, intent, junction_kind(net, j.junction),
                                j.junction, end=junction_exit(net, j)))
        i += 1
    turns = list(out)
    for c in scenario.route.lane_changes:
        left = c.direction == "left"
        out.append(Maneuver(f"lane_change_{c.direction}", lane_change_pos(c.pos, c.lanes, junctions, turns),
                            Intent.LANE_LEFT if left else Intent.LANE_RIGHT, lanes=c.lanes))
    out.sort(key=lambda m: (m.pos, m.kind))
    return out
