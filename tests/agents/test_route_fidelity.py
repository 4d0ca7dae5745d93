"""The route-oracle on routes of kinds that real leaderboard files hold and LangAuto's do not
(``../shared/carla/FINDINGS-2.md``), each built here on a bundled town and driven in SUMO."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from icrsumo.networks import load_net
from icrsumo.resources import bundled_towns
from icrsumo.routes import format_routes
from icrsumo.types import RouteSpec, Waypoint


def route_through(town: str, edges: list[str], start: float = 10.0, end: float | None = None,
                  lane: int = 0) -> RouteSpec:
    """A route (SUMO coordinates) with a waypoint on every edge of ``edges``: ``start`` m into
    the first, mid-edge on the others, ``end`` m into the last (default: its middle)."""
    net = load_net(bundled_towns()[town])
    pts = []
    for i, e in enumerate(edges):
        length = net.edge_length[e]
        pos = start if i == 0 else (end if (i == len(edges) - 1 and end is not None) else length / 2)
        ln = lane if i == 0 and lane in net.passenger_lanes[e] else net.passenger_lanes[e][0]
        x, y, h = net.lane_pose(f"{e}_{ln}", pos)
        pts.append(Waypoint(x=round(x, 2), y=round(y, 2), yaw=round(math.degrees(h), 2)))
    return RouteSpec(id="r", town=town, waypoints=tuple(pts))


def drive(tmp_path: Path, spec: RouteSpec, traffic: str = "normal", edit=None, callbacks=()):
    """Convert ``spec``, generate its instructions and drive its baseline with the route-oracle:
    (scenario, episode log, result). ``edit(sumocfg_text) -> text`` changes the scenario's
    SUMO configuration first."""
    from icrsumo.agents.privileged import RouteOracle
    from icrsumo.convert import ConvertOptions, convert_routes
    from icrsumo.instructions.generate import GenerateOptions, generate
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.metrics import score_episode
    from icrsumo.scenario import read_scenario
    from icrsumo.sim.episode import run_episode

    f = tmp_path / "route.xml"
    f.write_text(format_routes([spec]))
    report = convert_routes(f, tmp_path / "conv", ConvertOptions(coords="sumo", traffic=traffic, workers=1))
    assert not report.failures, report.failures
    sc_dir = tmp_path / "conv" / "scenarios" / spec.id
    _, failures = generate(sc_dir, tmp_path / "instr", GenerateOptions(workers=1))
    assert not failures, failures
    if edit is not None:
        cfg = sc_dir / "scenario.sumocfg"
        cfg.write_text(edit(cfg.read_text(encoding="utf-8")), encoding="utf-8")
    scenario = read_scenario(sc_dir)
    instructions = read_instruction_sets(tmp_path / "instr" / f"{spec.id}.json")[0]
    log = run_episode(scenario, instructions, RouteOracle(), callbacks=callbacks)
    return scenario, log, score_episode(log)


#: class A: around a block and back onto the first road, which the route then leaves straight on
#: (the first visit turned right there)
REVISIT = ("icr_grid", ["E_J0_2_J0_3", "E_J0_3_J1_3", "E_J1_3_J1_2", "E_J1_2_J0_2", "E_J0_2_J0_3",
                        "E_J0_3_J0_4"])


@pytest.mark.sumo
def test_route_oracle_leaves_a_revisited_road_the_way_the_route_does(tmp_path):
    town, edges = REVISIT
    scenario, log, result = drive(tmp_path, route_through(town, edges))
    assert list(scenario.ego_edges) == edges  # the route drives the first road twice
    assert log.termination == "completed" and result.rc == 100.0 and result.ds == 100.0


def _world(net, ego, vehicles):
    import numpy as np

    from icrsumo.agents.base import World

    return World(net=net, ego=ego, lane="", lane_pos=0.0,
                 vehicles=np.array(vehicles, dtype=float).reshape(-1, 5), pedestrians=np.zeros((0, 2)),
                 tl_states={}, route=None, progress=0.0)


@pytest.mark.parametrize(("back", "speed", "free"), [
    (10.0, 12.0, False),   # class C: 10 m behind the rear at 12 m/s reaches the ego in < 1 s
    (45.0, 12.0, True),    # 3.75 s away
    (10.0, 0.0, True),     # standing
    (2.0, 0.0, False),     # beside the ego's footprint
])
def test_lane_change_gap_is_judged_by_time_to_reach_the_ego(back, speed, free):
    """Class C (FINDINGS-2): a change from a standstill into a lane where a car comes up fast."""
    import numpy as np

    from icrsumo.agents.privileged import RouteOracle
    from icrsumo.dynamics import EgoState

    net = load_net(bundled_towns()["Town06"])
    edge = next(e for e in sorted(net.passenger_lanes) if len(net.passenger_lanes[e]) >= 3
                and net.edge_length[e] > 150)
    lanes = net.passenger_lanes[edge]
    oracle = RouteOracle()
    oracle.net = net
    length = oracle.params.length
    pos = 100.0
    fx, fy, h = net.lane_pose(f"{edge}_{lanes[0]}", pos)
    ego = EgoState(fx - 0.5 * length * math.cos(h), fy - 0.5 * length * math.sin(h), h, 0.0)
    tx, ty, th = net.lane_pose(f"{edge}_{lanes[1]}", pos)
    centre = -(length + back + 2.4)     # its front `back` m behind the ego's rear (car 4.8 m)
    car = [tx + centre * math.cos(th), ty + centre * math.sin(th), th, 4.8, 1.9]
    oracle._speeds = np.array([speed])
    assert oracle._lane_free(_world(net, ego, [car]), edge, lanes[1], pos) is free


@pytest.mark.sumo
def test_fleet_cap_holds_background_traffic_and_never_the_ego(tmp_path):
    """Class F: scenarios cap the background fleet (SUMO's max-num-vehicles); the ego is placed
    with moveToXY, which inserts it even when the cap is reached."""
    import re

    from icrsumo.sim.callbacks import EpisodeCallback

    class Count(EpisodeCallback):
        most = 0

        def on_step(self, episode, step):
            Count.most = max(Count.most, episode.backend.session.ls.vehicle.getIDCount())

    town, edges = REVISIT
    def cap3(text: str) -> str:
        return re.sub(r'max-num-vehicles value="\d+"', 'max-num-vehicles value="3"', text)

    scenario, log, result = drive(tmp_path, route_through(town, edges), edit=cap3, callbacks=[Count()])
    assert scenario.manifest["traffic"]["max_vehicles"] == round(10.0 * load_net(scenario.net).lane_km)
    assert log.termination == "completed"
    assert Count.most == 4  # three background vehicles and the ego


@pytest.mark.sumo
def test_sumo_never_teleports_the_ego_out_of_a_queue(tmp_path):
    """Class F: background vehicles stuck for 120 s are teleported (a jam dissolves before the
    leaderboard's 180 s blocked rule); the ego's vType opts out (timeToTeleport -1). On this
    route the ego queues behind a jam for more than 120 s: without the opt-out SUMO teleported
    it and the episode ended 'stuck' at RC 86.8."""
    from icrsumo.agents.privileged import RouteOracle
    from icrsumo.cache import bundled_route
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.scenario import read_scenario
    from icrsumo.sim.episode import run_episode

    sc_dir, instr = bundled_route("carla_fidelity_mixed_022", "carla-fidelity")
    scenario = read_scenario(sc_dir)
    assert 'timeToTeleport="-1"' in (sc_dir / "ego.rou.xml").read_text(encoding="utf-8")
    assert scenario.manifest["traffic"]["max_vehicles"] == 120   # Town03's leaderboard fleet
    log = run_episode(scenario, read_instruction_sets(instr)[0], RouteOracle())
    assert log.termination == "completed"
