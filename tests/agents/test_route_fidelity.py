"""The route-oracle on routes of kinds that real leaderboard files hold and LangAuto's do not
(``../shared/carla/FINDINGS-2.md``), each built here on a bundled town and driven in SUMO."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from icrsumo.core.resources import bundled_towns
from icrsumo.core.types import RouteSpec, Waypoint
from icrsumo.sim.callbacks import EpisodeCallback
from icrsumo.world.networks import load_net
from icrsumo.world.routes import format_routes


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
    from icrsumo.instructions.generate import GenerateOptions, generate
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.scoring import score_episode
    from icrsumo.sim.episode import run_episode
    from icrsumo.world.convert import ConvertOptions, convert_routes
    from icrsumo.world.scenario import read_scenario

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
    from icrsumo.world.dynamics import EgoState

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


@pytest.mark.parametrize(("speed", "coming"), [(11.5, True), (0.0, False)])
def test_a_car_coming_up_inside_the_junction_before_a_short_lane_is_seen(speed, coming):
    """Class C on a short target lane (``carla_fidelity_revisit_014``, Town10HD): edge ``-14``
    is 9.2 m long, so a car 20 m behind the ego is still on the internal lane of the junction
    before it, off the lane's own polyline. The follower moved from lane 2 to lane 1 for its
    right turn at 2 m/s and a car at 11.5 m/s ran into it; the check now looks back along the
    ways into the lane (the internal lanes of the connections into it). A car standing there
    does not come up."""
    import numpy as np

    from icrsumo.agents.privileged import InstructionFollower
    from icrsumo.world.dynamics import EgoState

    net = load_net(bundled_towns()["Town10HD"])
    assert net.edge_length["-14"] < 10.0
    driver = InstructionFollower()
    driver.net = net
    length = driver.params.length
    pos = 6.0                                  # the ego's front, on lane 2, wanting lane 1
    fx, fy, h = net.lane_pose("-14_2", pos)
    ego = EgoState(fx - 0.5 * length * math.cos(h), fy - 0.5 * length * math.sin(h), h, 2.0)
    path, cum, start = driver._map().approaches("-14_1")[0]
    s_car = start + pos - length - 20.0 - 2.4   # its centre: its front 20 m behind the ego's rear
    i = int(np.searchsorted(cum, s_car)) - 1
    t = (s_car - cum[i]) / (cum[i + 1] - cum[i])
    (x0, y0), (x1, y1) = path[i], path[i + 1]
    car = [x0 + t * (x1 - x0), y0 + t * (y1 - y0), math.atan2(y1 - y0, x1 - x0), 4.8, 1.9]
    assert not any(lane.startswith("-14_") for lane, *_ in net.project(car[0], car[1], 1.0))
    assert 0.0 < s_car < start                  # on the internal lane before the edge
    driver._speeds = np.array([speed])
    assert driver._coming_up(_world(net, ego, [car]), "-14", 1, pos) is coming


@pytest.mark.sumo
def test_fleet_cap_holds_background_traffic_and_never_the_ego(tmp_path):
    """Class F: scenarios cap the background fleet (SUMO's max-num-vehicles); the ego is placed
    with moveToXY, which inserts it even when the cap is reached."""
    import re

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
    from icrsumo.evaluation.bundled import bundled_route
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.sim.episode import run_episode
    from icrsumo.world.scenario import read_scenario

    sc_dir, instr = bundled_route("carla_fidelity_mixed_022", "carla-fidelity")
    scenario = read_scenario(sc_dir)
    assert 'timeToTeleport="-1"' in (sc_dir / "ego.rou.xml").read_text(encoding="utf-8")
    assert scenario.manifest["traffic"]["max_vehicles"] == 120   # Town03's leaderboard fleet
    log = run_episode(scenario, read_instruction_sets(instr)[0], RouteOracle())
    assert log.termination == "completed"


@pytest.mark.sumo
def test_a_left_turner_waiting_for_a_gap_does_not_hold_the_queue_behind_it_forever():
    """Class F: on Town04's downtown (``carla_fidelity_mixed_024``) a background car waits at a
    permissive green to turn left across a steady oncoming stream, cycle after cycle (its
    waiting time restarts whenever it creeps), with the ego queued behind it on a one-lane
    approach: the ego stood there past the blocked rule (DS 56.3). Scenarios make a background
    driver fully impatient after IMPATIENCE_S s of waiting (SUMO's --time-to-impatience,
    default 180 s): it then takes a gap that makes the oncoming car brake."""
    from icrsumo.agents.privileged import RouteOracle
    from icrsumo.evaluation.bundled import bundled_route
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.scoring import score_episode
    from icrsumo.sim.episode import run_episode
    from icrsumo.world.convert import IMPATIENCE_S
    from icrsumo.world.scenario import read_scenario

    sc_dir, instr = bundled_route("carla_fidelity_mixed_024", "carla-fidelity")
    cfg = (sc_dir / "scenario.sumocfg").read_text(encoding="utf-8")
    assert f'<time-to-impatience value="{IMPATIENCE_S:.0f}"/>' in cfg
    log = run_episode(read_scenario(sc_dir), read_instruction_sets(instr)[0], RouteOracle())
    assert log.termination == "completed" and score_episode(log).ds == 100.0


class _OncomingAtGreen(EpisodeCallback):
    """Class D set-up on Town01's junction 54, where the left turn ``-1`` -> ``-25`` gets a
    permissive ``g`` in the same phase as the oncoming straight ``2`` -> ``1`` gets ``G``: the
    light is held red while the ego arrives, and an oncoming car stands at its line (its
    front ``4`` m before it) until ``release`` s after the green starts (None: never).
    Records the order in which the two pass the point where their paths cross."""

    def __init__(self, release: float | None) -> None:
        self.release = release
        self.order: list[tuple[str, float]] = []
        self.green: float | None = None

    def on_ready(self, episode):
        ls = episode.backend.session.ls
        ls.trafficlight.setPhase("54", 8)          # red for both movements
        ls.trafficlight.setPhaseDuration("54", 25.0)
        ls.route.add("oncoming", ["2", "1"])
        ls.vehicle.add("foe", "oncoming", departPos="38", departSpeed="0", departLane="1")

    def on_step(self, episode, step):
        ls = episode.backend.session.ls
        if "foe" not in ls.vehicle.getIDList():
            return
        if ls.trafficlight.getRedYellowGreenState("54")[5] == "G" and self.green is None:
            self.green = step.t
        go = self.green is not None and self.release is not None and step.t - self.green >= self.release
        ls.vehicle.setSpeed("foe", -1 if go else 0)
        for who, past in (("ego", (":54_6_0", "-25_1")), ("foe", ("1_1",))):
            if who not in {o for o, _ in self.order} and ls.vehicle.getLaneID(who) in past:
                self.order.append((who, step.t))


@pytest.mark.sumo
@pytest.mark.parametrize("release", [0.0, 0.5])
def test_permissive_left_waits_for_an_oncoming_car_that_stands_at_the_start_of_green(tmp_path, release):
    """Class D: the oncoming car stands at the head of its queue when the light turns green;
    it is about to go, and has the right of way (``G`` against the ego's ``g``). Before the
    fix the ego, seeing it stand, turned in front of it and crossed its path 0.7-1.0 s after
    it (a near miss 3.3 m apart); now it lets the car pass and follows it by more than 2 s."""
    setup = _OncomingAtGreen(release)
    _, log, result = drive(tmp_path, route_through("Town01", ["-1", "-25", "-10"], lane=1),
                           traffic="none", callbacks=[setup])
    assert log.termination == "completed" and result.ds == 100.0
    (first, t_first), (second, t_second) = setup.order
    assert (first, second) == ("foe", "ego") and t_second - t_first > 2.0


@pytest.mark.sumo
def test_permissive_left_waits_for_a_standing_queue_head_only_so_long(tmp_path):
    """Class D's wait is bounded: an oncoming car that never leaves its line (it may wait for
    something the ego cannot see) holds the ego for STANDING_WAIT s, not until the time-out."""
    from icrsumo.agents.speed import STANDING_WAIT

    setup = _OncomingAtGreen(None)
    _, log, result = drive(tmp_path, route_through("Town01", ["-1", "-25", "-10"], lane=1),
                           traffic="none", callbacks=[setup])
    assert log.termination == "completed" and result.ds == 100.0
    assert [o for o, _ in setup.order] == ["ego"]
    assert setup.order[0][1] - setup.green < STANDING_WAIT + 6.0


@pytest.mark.sumo
def test_red_light_is_judged_on_the_movement_the_ego_makes(tmp_path):
    """Class B: Town02's junction 400 gives its approach lane ``-0_1`` a right turn (``G``) and
    a straight-on movement (``r``) in one phase. This route drives straight through it first,
    loops round and comes back to turn right on that phase; at the turn SUMO reports the ego
    on the straight-on movement's internal lane for its first metres. Judged by that lane the
    ego ran a red light (DS 49.0 before the fix); judged by the movement it makes, none."""
    edges = ["-0", "-1", "-16", "12", "-3", "15", "14", "-10", "-11", "7", "18", "-2", "-0", "-4", "8"]

    class Lights(EpisodeCallback):
        def on_ready(self, episode):
            self.lanes: list[str] = []
            ls = episode.backend.session.ls
            ls.trafficlight.setPhase("400", 0)      # straight on: G
            ls.trafficlight.setPhaseDuration("400", 300.0)

        def on_step(self, episode, step):
            ls = episode.backend.session.ls
            lane = ls.vehicle.getLaneID("ego")
            if lane.startswith("-2_") and ls.trafficlight.getPhase("400") != 3:
                ls.trafficlight.setPhase("400", 3)  # right G, straight on r
                ls.trafficlight.setPhaseDuration("400", 300.0)
            if not self.lanes or self.lanes[-1] != lane:
                self.lanes.append(lane)

    cb = Lights()
    scenario, log, result = drive(tmp_path, route_through("Town02", edges, lane=1), traffic="none",
                                  callbacks=[cb])
    second = cb.lanes[cb.lanes.index("-2_1"):]
    assert second[:3] == ["-2_1", ":2.0_1_0", "-0_1"] and ":400_5_0" in second   # SUMO's misreport
    assert log.termination == "completed"
    assert [e.kind for e in log.events] == [] and result.ds == 100.0


class _StandingPedestrian(EpisodeCallback):
    """A pedestrian held standing at (``x``, ``y``) m for the whole episode (SUMO's person
    moved there at every step); ``lane``: where SUMO has it."""

    def __init__(self, x: float, y: float) -> None:
        self.x, self.y, self.lane = x, y, ""

    def on_ready(self, episode):
        ls = episode.backend.session.ls
        ls.person.add("ped", "-25", 1.0)
        ls.person.appendWaitingStage("ped", 3600.0)

    def on_step(self, episode, step):
        ls = episode.backend.session.ls
        ls.person.moveToXY("ped", "", self.x, self.y, keepRoute=2)
        self.lane = ls.person.getLaneID("ped")


@pytest.mark.sumo
@pytest.mark.parametrize(("x", "where", "passes"), [
    (152.1, ":54_w2_0", True),    # on the kerb's walking area, 2.2 m beside the ego's path
    (153.3, ":54_c1_0", False),   # on the crossing, inside the ego's swept path
])
def test_a_pedestrian_standing_on_the_kerb_does_not_stop_the_ego(tmp_path, x, where, passes):
    """Class E: at Town01's junction 54 the ego turns left onto ``-25`` over the crossing
    ``:54_c1``; a pedestrian stands at its kerb. Counted within 2.5 m of the path, one 2.2 m
    away held the ego short of the crossing until the blocked rule ended the run (and SUMO's
    pedestrians do not step out in front of a car that close: a stand-off). A standing
    pedestrian now counts only inside the swept path (half the ego's width + 0.5 m)."""
    ped = _StandingPedestrian(x, 320.6)
    _, log, result = drive(tmp_path, route_through("Town01", ["-1", "-25", "-10"], lane=1),
                           traffic="none", callbacks=[ped])
    assert ped.lane == where
    assert (log.termination == "completed") is passes
    if not passes:
        assert log.termination == "agent_blocked"
        assert not any(e.kind == "collision_pedestrian" for e in log.events)


#: the ego's pose (centre x, y m, yaw rad) where the route-oracle of commit 840a9fb got a
#: roadside event on carla_fidelity_mixed_000 (Town01, t = 57.5 s): one footprint corner in a
#: wedge between two lanes' flat-capped outlines that no junction outline covers, the other
#: cutting the inner edge of the bend by centimetres
SLIVER_POSE = (7.293289082566637, 325.41250565204365, 0.5441762182272392)


def _outlines_only(net):
    """The drivable area as it was built before class G's fix: lane and junction outlines,
    no joints, no closing, no tolerance."""
    import shapely

    from icrsumo.sim.drivable import DrivableArea, carriageway, lane_polygons, polygonal

    return DrivableArea(polygonal(shapely.union_all([*lane_polygons(net), carriageway(net)])))


def test_a_sliver_between_lane_outlines_is_drivable():
    """Class G at the pose where it happened: with the outlines alone two corners of the
    footprint are off at once (a roadside event, DS 65.0 on that route); with the drivable area
    as built now (joints, 5 cm closing, 0.1 m tolerance) none is."""
    from icrsumo.sim.drivable import drivable_area
    from icrsumo.sim.sensors import off_corners
    from icrsumo.world.dynamics import EgoState

    net = load_net(bundled_towns()["Town01"])
    ego = EgoState(*SLIVER_POSE, 0.0)
    assert off_corners(ego, (4.9, 2.1), _outlines_only(net).count_off) == 2
    assert off_corners(ego, (4.9, 2.1), drivable_area(net).count_off) == 0


@pytest.mark.sumo
def test_the_sliver_route_drives_without_a_roadside_event():
    """carla_fidelity_mixed_000 (Town01), the route of class G's event, driven in SUMO: no
    roadside event, and nowhere on it are two corners off the area as built now."""
    from icrsumo.agents.privileged import RouteOracle
    from icrsumo.evaluation.bundled import bundled_route
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.scoring import score_episode
    from icrsumo.sim.drivable import drivable_area
    from icrsumo.sim.episode import run_episode
    from icrsumo.sim.sensors import off_corners
    from icrsumo.world.dynamics import EgoState
    from icrsumo.world.scenario import read_scenario

    sc_dir, instr = bundled_route("carla_fidelity_mixed_000", "carla-fidelity")
    scenario = read_scenario(sc_dir)
    log = run_episode(scenario, read_instruction_sets(instr)[0], RouteOracle())
    assert log.termination == "completed" and score_episode(log).ds == 100.0
    now = drivable_area(load_net(scenario.net))
    size = (float(scenario.manifest["ego"]["length"]), float(scenario.manifest["ego"]["width"]))
    assert max(off_corners(EgoState(x, y, h, 0.0), size, now.count_off)
               for x, y, h in zip(log.x, log.y, log.yaw)) <= 1


@pytest.mark.sumo
def test_routes_that_end_inside_a_junction_or_loop_onto_their_start_convert_and_drive(tmp_path):
    """Bad input of issue 27: a last waypoint inside junction 54 (on the left turn's internal
    lane) stands for the end of the turn's incoming edge, where the route then ends; a route
    that comes back round a block onto the road it started on and ends there drives the loop.
    Neither circles nor stalls."""
    net = load_net(bundled_towns()["Town01"])
    x, y, h = net.lane_pose(":54_1_0", 8.0)
    start = route_through("Town01", ["-1", "-25"], lane=1).waypoints[0]
    ends = RouteSpec(id="ends", town="Town01",
                     waypoints=(start, Waypoint(x=round(x, 2), y=round(y, 2), yaw=round(math.degrees(h), 2))))
    loop = route_through("Town01", ["-1", "-25", "-10", "16", "-1"], lane=1, end=100.0)
    for spec, edges in ((ends, ["-1"]), (loop, ["-1", "-25", "-10", "16", "-1"])):
        out = tmp_path / spec.id
        out.mkdir()
        scenario, log, result = drive(out, spec, traffic="none")
        assert list(scenario.ego_edges) == edges
        assert log.termination == "completed" and result.ds == 100.0


@pytest.mark.sumo
@pytest.mark.parametrize(("route", "before"), [
    ("carla_fidelity_lanes_000", "class C: a change given up for a gap was resumed into the car beside"),
    ("carla_fidelity_mixed_046", "class C: a change under way into a car coming up on a curved lane"),
    ("carla_fidelity_junctions_006", "a car at 13 m/s rear-ended the ego half a second after its start"),
])
def test_traced_fidelity_routes_drive_clean(route, before):
    """Routes of the fidelity suite whose vehicle collisions were traced and fixed
    (docs/fidelity.md); each had DS 60.0 before."""
    from icrsumo.agents.privileged import RouteOracle
    from icrsumo.evaluation.bundled import bundled_route
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.scoring import score_episode
    from icrsumo.sim.episode import run_episode
    from icrsumo.world.scenario import read_scenario

    sc_dir, instr = bundled_route(route, "carla-fidelity")
    log = run_episode(read_scenario(sc_dir), read_instruction_sets(instr)[0], RouteOracle())
    assert log.termination == "completed" and score_episode(log).ds == 100.0, before


@pytest.mark.sumo
def test_instruction_follower_chooses_again_when_a_new_instruction_comes_before_the_junction():
    """carla_fidelity_junctions_009 (Town05) starts a few metres before a junction: the
    follower chose its branch under the first instruction ("Prepare to change to the left
    lane.") and went straight on before "At the traffic light, turn left." became active
    (route deviation at RC 2.4). A new instruction before the junction's entry now reopens
    the choice."""
    from icrsumo.agents.privileged import InstructionFollower
    from icrsumo.evaluation.bundled import bundled_route
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.scoring import score_episode
    from icrsumo.sim.episode import run_episode
    from icrsumo.world.scenario import read_scenario

    sc_dir, instr = bundled_route("carla_fidelity_junctions_009", "carla-fidelity")
    log = run_episode(read_scenario(sc_dir), read_instruction_sets(instr)[0], InstructionFollower())
    assert log.termination == "completed" and score_episode(log).rc == 100.0


class _Passed(Exception):
    """Raised by :class:`_StopPast` once the ego is past the stretch a test is about."""


class _StopPast(EpisodeCallback):
    """Ends an episode (by raising _Passed) once the route progress passes ``until`` m."""

    def __init__(self, until: float) -> None:
        self.until = until

    def on_step(self, episode, step) -> None:
        if step.progress > self.until:
            raise _Passed


@pytest.mark.sumo
@pytest.mark.parametrize(("route", "until", "before"), [
    ("carla_fidelity_highway_003", 260.0, "inside a 52 m junction the follower had chosen the branch at "
     "the 2 m edge beyond it under the previous instruction (turn right): deviation at RC 16.0"),
    ("carla_fidelity_junctions_006", 480.0, "a right turn, a straight and a left within 30 m: each next "
     "instruction came after its junction was entered, and the right turn was made again: RC 24.9"),
    ("carla_fidelity_highway_006", 330.0, "a lane change asked for on a 3.7 m edge, the left turn after it "
     "announced 1.9 m before its junction: RC 16.4"),
    ("carla_fidelity_lanes_009", 320.0, "a change across 4 lanes asked for by one instruction naming "
     "one lane: RC 16.1"),
])
def test_instruction_follower_follows_closely_spaced_maneuvers(route, until, before):
    """Misses of the instruction-follower on routes the oracle completes, traced to when the
    baseline instructions came (layout 1) and how the follower used them (docs/fidelity.md):
    now the follower reaches ``until`` m without a route deviation."""
    from icrsumo.agents.privileged import InstructionFollower
    from icrsumo.evaluation.bundled import bundled_route
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.sim.episode import run_episode
    from icrsumo.world.scenario import read_scenario

    sc_dir, instr = bundled_route(route, "carla-fidelity")
    with pytest.raises(_Passed):
        log = run_episode(read_scenario(sc_dir), read_instruction_sets(instr)[0], InstructionFollower(),
                          callbacks=[_StopPast(until)])
        pytest.fail(f"{log.termination.value} at {log.termination_t:.1f} s: {before}")


def _follower_on(town: str, intent, text: str = ""):
    from icrsumo.agents.privileged import _RING_WORDS, InstructionFollower

    f = InstructionFollower()
    f.net = load_net(bundled_towns()[town])
    f.intent = intent
    f._ring_named = bool(_RING_WORDS.search(text))
    return f


def test_a_roundabout_instruction_takes_the_ring_not_the_slip_road():
    """Town03, edge 34 (carla_fidelity_junctions_005): the approach offers the roundabout
    (-36, straight on) and a slip road to the right (15). "Take the first exit out of the
    roundabout." reads as right: the follower took the slip road and left the route."""
    from icrsumo.core.types import Intent

    f = _follower_on("Town03", Intent.RIGHT, "Take the first exit out of the roundabout.")
    assert "-36" in f.net.roundabout_edges and "15" not in f.net.roundabout_edges
    assert f.choose(None, "34", ["-36", "15"], tentative=False) == "-36"
    # a plain right turn there still takes the slip road
    plain = _follower_on("Town03", Intent.RIGHT, "Turn right.")
    assert plain.choose(None, "34", ["-36", "15"], tentative=False) == "15"


def test_an_instruction_is_used_up_by_the_junction_it_names():
    """Town04 (carla_fidelity_junctions_006): "Make a right turn at the traffic light." is
    carried out at the end of edge 25; 3.6 m later, at the end of edge 13, the route goes
    straight on (12). The follower turned right again (21) before the next instruction came."""
    from icrsumo.core.types import Intent

    f = _follower_on("Town04", Intent.RIGHT, "Make a right turn at the traffic light.")
    assert f.choose(None, "25", ["-14", "13", "24"], tentative=False) == "13"
    assert f.choose(None, "13", ["12", "21"], tentative=True) == "12"
    assert f.choose(None, "13", ["12", "21"], tentative=False) == "12"
    # the same junction may be chosen again (a replan) and keeps the instruction's branch
    assert f.choose(None, "25", ["-14", "13", "24"], tentative=False) == "13"
