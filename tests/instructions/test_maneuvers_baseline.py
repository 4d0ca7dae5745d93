"""Maneuvers from route geometry and the baseline sequences built from them."""

from __future__ import annotations

from collections import Counter

from icrsumo.core.types import Intent, JunctionPass, Maneuver
from icrsumo.instructions.banks import load_banks
from icrsumo.instructions.baseline import NEXT_ROOM_M, build_baseline
from icrsumo.instructions.intent import classify_intent
from icrsumo.instructions.maneuvers import extract_maneuvers, lane_change_pos, roundabout_intent
from icrsumo.instructions.store import read_instruction_sets
from icrsumo.world.networks import load_net
from icrsumo.world.scenario import find_scenarios, read_scenario


def _all(converted):
    for split, d in converted.items():
        for sd in find_scenarios(d):
            sc = read_scenario(sd)
            yield split, sc, extract_maneuvers(sc, load_net(sc.net))


def test_maneuvers_cover_junction_kinds_and_lane_changes(converted):
    kinds, junctions = Counter(), Counter()
    for _, sc, ms in _all(converted):
        assert [m.pos for m in ms] == sorted(m.pos for m in ms)
        assert all(0 <= m.pos <= sc.length for m in ms)
        choice = sum(1 for j in sc.route.junctions if j.choice)
        assert sum(1 for m in ms if not m.kind.startswith("lane")) >= min(1, choice)
        kinds.update(m.kind for m in ms)
        junctions.update(m.junction for m in ms)
    for k in ("turn_left", "turn_right", "straight", "roundabout", "lane_change_left",
              "lane_change_right"):
        assert kinds[k] > 0, kinds
    for j in ("traffic_light", "stop_sign", "t_junction", "crossroad", "roundabout"):
        assert junctions[j] > 0, junctions


def test_roundabout_exit_numbers(converted):
    seen = set()
    for _, _sc, ms in _all(converted):
        for m in ms:
            if m.kind == "roundabout":
                assert m.exit >= 1 and m.intent == roundabout_intent(m.exit)
                seen.add(m.exit)
    assert len(seen) >= 2
    assert roundabout_intent(1) == Intent.RIGHT and roundabout_intent(2) == Intent.STRAIGHT
    assert roundabout_intent(3) == Intent.LEFT


def test_baseline_sequences(converted, generated):
    counts = {}
    for split, d in generated.items():
        n = []
        for f in sorted(d.glob("*.json")):
            if f.name == "index.json":
                continue
            base = read_instruction_sets(f)[0]
            ins = base.instructions
            assert base.family == "baseline" and [i.id for i in ins] == list(range(len(ins)))
            assert all(b.trigger > a.trigger for a, b in zip(ins, ins[1:]))
            assert ins[0].trigger == 0.0
            for i in ins:
                assert ("[x]" in i.text) == (i.distance is not None)
                assert "{" not in i.text
                assert classify_intent(i.text) == i.intent, i.text
                assert "[x]" not in i.rendered()
            n.append(len(ins))
        counts[split] = sum(n) / len(n)
    assert 2.0 <= counts["tiny"] <= 6.5
    assert counts["long"] >= 9


def test_baseline_is_deterministic_per_route_seed(converted):
    banks = load_banks()
    _, sc, ms = next(_all(converted))
    a = build_baseline(sc.route_id, sc.length, ms, banks, sc.seed)
    b = build_baseline(sc.route_id, sc.length, ms, banks, sc.seed)
    c = build_baseline(sc.route_id, sc.length, ms, banks, sc.seed + 1)
    assert a == b
    assert [i.trigger for i in a.instructions] == [i.trigger for i in c.instructions]


def test_junction_maneuvers_end_where_the_junction_is_left(converted):
    for _, sc, ms in _all(converted):
        for m in ms:
            if m.kind.startswith("lane_change"):
                assert m.end == 0.0
            else:
                assert m.pos < m.end <= sc.length + 1.0, (sc.route_id, m)


def test_no_instruction_replaces_a_maneuver_inside_its_junction(converted):
    """While the ego is inside a junction maneuver's junction (entry to exit), the active
    instruction is that maneuver's, unless the next junction starts before this one's exit
    plus 5 m (then the next one's comes at the exit at the earliest), or less than NEXT_ROOM_M
    past the exit (then it comes NEXT_ROOM_M before the next junction, never before the ego has
    entered this one; a roundabout keeps its instruction until NEXT_ROOM_M before its exit)."""
    banks = load_banks()
    for _, sc, ms in _all(converted):
        ins = build_baseline(sc.route_id, sc.length, ms, banks, sc.seed).instructions
        junction = [m for m in ms if not m.kind.startswith("lane_change")]
        for a, b in zip(junction, junction[1:] + [None]):
            inside = a.pos + 1.0 if a.kind != "roundabout" else max(a.pos + 1.0, a.end - NEXT_ROOM_M)
            for i in ins:
                if a.pos < i.trigger < a.end + 4.99:
                    assert i.maneuver_pos == round(a.pos, 2) or (
                        b is not None and i.maneuver_pos == round(b.pos, 2) and (
                            (b.pos < a.end + 5.0 and i.trigger >= a.end)
                            or (b.pos < a.end + NEXT_ROOM_M and i.trigger >= inside - 1e-6
                                and i.trigger >= b.pos - NEXT_ROOM_M - 1e-6))), (sc.route_id, a, i)


def _sequence(maneuvers: list[Maneuver], length: float = 600.0):
    return build_baseline("r", length, maneuvers, load_banks(), 7).instructions


def test_a_wide_junction_keeps_its_instruction_until_it_is_left():
    left = Maneuver("turn_left", 100.0, Intent.LEFT, "traffic_light", "j1", end=140.0)
    right = Maneuver("turn_right", 400.0, Intent.RIGHT, "crossroad", "j2", end=415.0)
    ins = _sequence([left, right])
    after = [i for i in ins if i.trigger > 100.0]
    assert after[0].trigger == 145.0 and after[0].intent == Intent.FOLLOW
    # a junction a few metres behind the wide one is announced inside it, 20 m before its
    # own entry: a driver must know the branch before the short edge between them
    close = Maneuver("turn_right", 143.0, Intent.RIGHT, "crossroad", "j2", end=160.0)
    ins = _sequence([left, close])
    nxt = next(i for i in ins if i.maneuver_pos == 143.0)
    assert nxt.trigger == 123.0 and nxt.intent == Intent.RIGHT
    assert all(i.maneuver_pos == 100.0 for i in ins if 100.0 < i.trigger < 123.0)
    # ... but never before the ego is in the last junction (1 m past its entry)
    short = Maneuver("turn_left", 100.0, Intent.LEFT, "traffic_light", "j1", end=110.0)
    ins = _sequence([short, Maneuver("straight", 115.0, Intent.STRAIGHT, "crossroad", "j2", end=130.0)])
    assert next(i for i in ins if i.maneuver_pos == 115.0).trigger == 101.0
    # 20 m or more past the exit: announced once the last junction is left, as before
    far = Maneuver("turn_right", 170.0, Intent.RIGHT, "crossroad", "j2", end=185.0)
    ins = _sequence([left, far])
    assert next(i for i in ins if i.maneuver_pos == 170.0).trigger == 145.0


def test_a_lane_change_stays_on_30_m_per_lane_to_cross():
    turn = Maneuver("turn_right", 400.0, Intent.RIGHT, "crossroad", "j1", end=415.0)
    for lanes, on_for in ((1, 30.0), (2, 60.0), (3, 90.0)):
        change = Maneuver("lane_change_right", 100.0, Intent.LANE_RIGHT, lanes=lanes)
        ins = _sequence([change, turn])
        i = next(k for k, x in enumerate(ins) if x.intent == Intent.LANE_RIGHT)
        # one instruction per lane (the phrasings name one lane), 30 m apart
        assert [x.trigger for x in ins[i:i + lanes]] == [100.0 + 30.0 * k for k in range(lanes)]
        assert all(x.intent == Intent.LANE_RIGHT for x in ins[i:i + lanes])
        assert ins[i + lanes].trigger == 100.0 + on_for and ins[i + lanes].intent != Intent.LANE_RIGHT
    # never longer than half the room before the junction where the lane matters
    change = Maneuver("lane_change_right", 300.0, Intent.LANE_RIGHT, lanes=3)
    ins = _sequence([change, turn])
    i = next(k for k, x in enumerate(ins) if x.intent == Intent.LANE_RIGHT)
    assert [x.trigger for x in ins[i:i + 4]] == [300.0, 316.67, 333.33, 350.0]


def test_a_lane_change_on_a_short_edge_is_asked_for_where_it_fits():
    """A lane change the route builder puts on an edge a few metres long (between two junctions
    of a CARLA town) comes back to where it fits, leaving room for the turn's announcement, but
    not before the previous junction maneuver's exit."""
    turns = [Maneuver("turn_right", 100.0, Intent.RIGHT, "traffic_light", "j0", end=120.0)]
    junctions = [JunctionPass(f"j{i}", "priority", "a", "b", 0, 0, ":j_0_0", "s", True, False, pos)
                 for i, pos in enumerate((100.0, 150.0, 240.0))]
    # 4 m before the junction: one lane needs 30 m, plus 50 m for the turn's announcement
    assert lane_change_pos(236.0, 1, junctions, turns) == 160.0
    assert lane_change_pos(236.0, 2, junctions, turns) == 130.0
    assert lane_change_pos(236.0, 4, junctions, turns) == 120.0   # the last exit at the earliest
    assert lane_change_pos(180.0, 1, junctions, turns) == 180.0   # 60 m of room: where it was


def test_lane_changes_count_the_lanes_they_cross(converted):
    seen = set()
    for _, sc, ms in _all(converted):
        changes = sc.route.lane_changes
        got = [m for m in ms if m.kind.startswith("lane_change")]
        assert sorted(m.lanes for m in got) == sorted(abs(c.to_lane - c.from_lane) for c in changes)
        seen.update(m.lanes for m in got)
    assert 1 in seen


def test_varied_leads_move_only_when_instructions_arrive():
    """Training data's varied leads (``icrsumo collect --vary-leads``): the same instruction
    types, intents and phrasings at other triggers, each drawn within VARIED_LEADS (m before its
    junction), a distance instruction naming its own lead; the same Generator seed gives the same
    sequence; without a Generator, the fixed layout."""
    import numpy as np

    from icrsumo.instructions.baseline import FIXED_LEADS, VARIED_LEADS, Leads

    ms = [Maneuver("turn_left", 300.0, Intent.LEFT, "traffic_light", "j1", end=320.0),
          Maneuver("straight", 700.0, Intent.STRAIGHT, "crossroad", "j2", end=715.0),
          Maneuver("turn_right", 1100.0, Intent.RIGHT, "t_junction", "j3", end=1112.0),
          Maneuver("turn_left", 1130.0, Intent.LEFT, "crossroad", "j4", end=1145.0)]
    fixed = build_baseline("r", 1400.0, ms, load_banks(), 7).instructions
    assert fixed == build_baseline("r", 1400.0, ms, load_banks(), 7, lead_rng=None).instructions
    assert Leads(50.0, 80.0, 20.0, 150.0, NEXT_ROOM_M) == FIXED_LEADS
    assert all(VARIED_LEADS[k][0] <= getattr(FIXED_LEADS, k) <= VARIED_LEADS[k][1] for k in Leads._fields)
    runs = [build_baseline("r", 1400.0, ms, load_banks(), 7,
                           lead_rng=np.random.default_rng([s, 1])).instructions for s in range(20)]
    assert runs[0] == build_baseline("r", 1400.0, ms, load_banks(), 7,
                                     lead_rng=np.random.default_rng([0, 1])).instructions
    for ins in runs:
        key = [(i.type, i.intent, i.maneuver_pos) for i in ins if i.maneuver_pos is not None]
        assert key == [(i.type, i.intent, i.maneuver_pos) for i in fixed if i.maneuver_pos is not None]
        assert [i.text for i in ins if i.distance is None] == [i.text for i in fixed if i.distance is None]
        assert all(b.trigger > a.trigger for a, b in zip(ins, ins[1:]))
        for i in ins:
            if i.maneuver_pos is not None and i.maneuver_pos < 1110.0:  # not inside j3
                assert 10.0 - 1e-6 <= i.maneuver_pos - i.trigger <= 120.0 + 1e-6, i
            if i.distance is not None and i.maneuver_pos is not None:
                assert abs(i.distance - (i.maneuver_pos - i.trigger)) <= 5.0 + 1e-6, i
    leads = {round(i.maneuver_pos - i.trigger) for ins in runs for i in ins if i.maneuver_pos == 300.0}
    assert len(leads) > 10   # the far and near announcements of one turn arrive all over
    # j4, 18 m past j3's exit, is announced inside j3 (1 m past its entry) at least as often
    # as the fixed layout does, and earlier whenever the drawn room reaches back there
    inside = [next(i for i in ins if i.maneuver_pos == 1130.0).trigger for ins in runs]
    assert all(1101.0 - 1e-6 <= t <= 1110.0 for t in inside)
