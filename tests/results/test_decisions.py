"""Decision-level attribution on hand-built episode logs (no SUMO): the decision classifier,
first divergence, and the per-family aggregation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from records_example import rec

from icrsumo.core.types import EpisodeLog, Instruction, InstructionSet, Intent, Maneuver
from icrsumo.core.vocab import DecisionOutcome as O
from icrsumo.core.vocab import Family, Termination
from icrsumo.results.aggregate import summarize
from icrsumo.results.attribution import attribution_doc, block_stats, flips, template_ranking
from icrsumo.results.decisions import classify_decisions, divergence, turn_of

#: a route of 300 m: a left turn at 50 m (junction over at 65 m), a required lane change to
#: the left at 120 m, straight on at 200 m (over at 215 m), and a follow stretch (no decision)
MANEUVERS = (
    Maneuver("turn_left", 50.0, Intent.LEFT, "crossroad", "J1", end=65.0),
    Maneuver("follow", 70.0, Intent.FOLLOW, length=40.0),
    Maneuver("lane_change_left", 120.0, Intent.LANE_LEFT, lanes=1),
    Maneuver("straight", 200.0, Intent.STRAIGHT, "traffic_light", "J2", end=215.0),
)


def _set(turn_text: str, family: str = "misleading", template: str = "M.left.p01") -> InstructionSet:
    ins = (
        Instruction(0, 0.0, "Follow the road.", Intent.FOLLOW, "start"),
        Instruction(1, 10.0, turn_text, Intent.LEFT, "turn", maneuver_pos=50.0, template=template),
        Instruction(2, 110.0, "Change to the left lane.", Intent.LANE_LEFT, "lane_change",
                    maneuver_pos=120.0),
        Instruction(3, 150.0, "Go straight at the traffic light.", Intent.STRAIGHT, "straight",
                    maneuver_pos=200.0),
    )
    return InstructionSet("r1", Family(family), 0, 7, ins)


def _log(progress_end: float, termination: Termination, final_yaw: float = 0.0) -> EpisodeLog:
    """The ego drives east along the route to ``progress_end`` (m), then (if it deviates)
    30 m on with heading ``final_yaw`` (rad)."""
    prog = list(np.arange(0.0, progress_end + 0.5, 1.0))
    x, y, yaw = list(prog), [0.0] * len(prog), [0.0] * len(prog)
    if termination == Termination.ROUTE_DEVIATION:
        for i in range(1, 31):
            prog.append(progress_end)
            x.append(progress_end + i * math.cos(final_yaw))
            y.append(i * math.sin(final_yaw))
            yaw.append(final_yaw)
    n = len(prog)
    active = [max(i for i, t in enumerate((0.0, 10.0, 110.0, 150.0)) if t <= p) for p in prog]
    return EpisodeLog(
        route_id="r1", agent="a", family=Family.MISLEADING, k=0, seed=7, step_length=0.05, route_length=300.0,
        t=tuple(0.1 * i for i in range(n)), x=tuple(x), y=tuple(y), yaw=tuple(yaw), speed=(5.0,) * n,
        progress=tuple(prog), instruction=tuple(active), outside=(0,) * n, route_dist=(0.0,) * n, events=(),
        termination=termination, termination_t=0.1 * n)


def _outcomes(ds):
    return [d.outcome for d in ds]


def test_a_completed_episode_followed_the_route_at_every_decision():
    done = _log(300.0, Termination.COMPLETED)
    ds = classify_decisions(MANEUVERS, _set("Turn right at the intersection."), done)
    assert [d.kind for d in ds] == ["turn_left", "lane_change_left", "straight"]  # follow is none
    assert _outcomes(ds) == [O.FOLLOWED_ROUTE] * 3
    assert [d.executed for d in ds] == [Intent.LEFT, Intent.LANE_LEFT, Intent.STRAIGHT]
    assert ds[0].text_intent == Intent.RIGHT and ds[0].contradicted and ds[0].template == "M.left.p01"


@pytest.mark.parametrize("text, final_yaw, outcome, executed", [
    ("Turn right at the intersection.", -math.pi / 2, O.FOLLOWED_TEXT, Intent.RIGHT),  # obeyed the lie
    ("Turn right at the intersection.", 0.0, O.OTHER, Intent.STRAIGHT),  # went straight instead
    ("Turn left at the intersection.", -math.pi / 2, O.OTHER, Intent.RIGHT),  # the text was right
    ("", -math.pi / 2, O.OTHER, Intent.RIGHT),  # a blank text names no branch
])
def test_a_deviation_at_a_decision(text, final_yaw, outcome, executed):
    ds = classify_decisions(MANEUVERS, _set(text), _log(58.0, Termination.ROUTE_DEVIATION, final_yaw))
    assert _outcomes(ds) == [outcome, O.NOT_REACHED, O.NOT_REACHED]
    assert ds[0].executed == executed and ds[0].instruction_id == 1
    assert divergence(ds) is ds[0]


def test_a_deviation_between_decisions_is_charged_to_none_and_a_timeout_reaches_nothing_more():
    ds = classify_decisions(MANEUVERS, _set("Turn left."), _log(140.0, Termination.ROUTE_DEVIATION, 1.2))
    assert _outcomes(ds) == [O.FOLLOWED_ROUTE, O.FOLLOWED_ROUTE, O.NOT_REACHED]  # 140 < 200 - 40
    ds = classify_decisions(MANEUVERS, _set("Turn left."), _log(100.0, Termination.ROUTE_TIMEOUT))
    assert _outcomes(ds) == [O.FOLLOWED_ROUTE, O.NOT_REACHED, O.NOT_REACHED]
    assert divergence(ds) is ds[1]


def test_turn_of_reads_the_heading_change():
    assert turn_of(0.0, 1.2) == Intent.LEFT and turn_of(3.0, -3.0) == Intent.STRAIGHT  # wraps
    assert turn_of(0.2, -1.0) == Intent.RIGHT and turn_of(0.0, 0.5) == Intent.STRAIGHT


def test_aggregation_compliance_confusion_flips_and_templates():
    done = _log(300.0, Termination.COMPLETED)
    base = classify_decisions(MANEUVERS, _set("Turn left.", "baseline", ""), done)
    obey = classify_decisions(MANEUVERS, _set("Turn right."), _log(58.0, Termination.ROUTE_DEVIATION, -1.5))
    resist = classify_decisions(MANEUVERS, _set("Turn right.", template="M.left.p02"),
                                _log(300.0, Termination.COMPLETED))
    st = block_stats([obey, resist])
    assert st.decisions == {"followed_route": 3, "followed_text": 1, "other": 0, "not_reached": 2}
    assert st.compliance == 0.5 and st.adherence == 0.75
    assert st.confusion["right"] == {"left": 1, "right": 1}
    records = [rec("a", "r1", "baseline", 0, 100, 100), rec("a", "r1", "misleading", 0, 20, 20, cls="RD"),
               rec("a", "r1", "misleading", 1, 100, 100)]
    decisions = {("a", "r1", "baseline", 0, 7): base, ("a", "r1", "misleading", 0, 7): obey,
                 ("a", "r1", "misleading", 1, 7): resist}
    rows = flips(records, decisions)
    assert len(rows) == 1 and rows[0]["k"] == 0
    assert rows[0]["decision"]["kind"] == "turn_left" and rows[0]["decision"]["outcome"] == "followed_text"
    assert rows[0]["instruction"] == {"id": 1, "text": "Turn right.", "template": "M.left.p01",
                                      "intent": "right"}
    ranking = template_ranking(rows, decisions)
    assert ranking[0] == {"family": "misleading", "template": "M.left.p01", "flips": 1, "uses": 1,
                          "flip_rate": 1.0, "example": "Turn right."}
    summary = summarize(records, suite="t", seed=7, k=2, families=("misleading",), n_boot=10,
                        decisions=decisions)
    a = summary.agents["a"]
    assert a.families["misleading"].decisions.compliance == 0.5 and a.baseline.decisions.compliance is None
    assert "compliance" not in summary.to_dict()["agents"]["a"]["baseline"]
    assert a.baseline.decisions.decisions["followed_route"] == 3
    bare = summarize(records, suite="t", seed=7, k=2, families=("misleading",), n_boot=10)
    assert bare.agents["a"].baseline.decisions is None  # without decisions, no statistics
    assert attribution_doc(records, decisions) == {"flips": rows, "templates": ranking}
