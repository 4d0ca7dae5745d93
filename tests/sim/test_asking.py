"""Asking for clarification: the navigator's rules on their own (the answer, the delay, once per
maneuver, how long the answer is shown), then in real SUMO episodes: the instruction-follower asks
where ambiguity leaves it unsure and follows the answer, an agent that asks at every step is
answered once per maneuver with every ask counted, asking changes nothing for agents that do not
ask, and ``icrsumo evaluate --asking`` stores and counts the asks."""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from icrsumo.agents.base import Action, AgentError
from icrsumo.agents.privileged import InstructionFollower, RouteOracle
from icrsumo.core.errors import InputError
from icrsumo.core.types import Instruction, Intent, Maneuver
from icrsumo.guards.base import FALLBACK_TEXT
from icrsumo.results.logs import ask_counts, dumps_log
from icrsumo.results.summary import Summary
from icrsumo.scoring import score_episode
from icrsumo.sim.asking import ASK_DELAY, Navigator
from icrsumo.sim.callbacks import EpisodeCallback
from icrsumo.sim.episode import RunOptions, run_episode

# --------------------------------------------------------------------------- the rules, no SUMO
MANEUVERS = (Maneuver("lane_change_left", 0.0, Intent.LANE_LEFT, lanes=1),
             Maneuver("turn_left", 50.0, Intent.LEFT, junction="traffic_light", junction_id="J", end=70.0))
BASELINE = (Instruction(0, 0.0, "Move into the left lane.", Intent.LANE_LEFT, "lane_change",
                        maneuver_pos=0.0),
            Instruction(1, 10.0, "Turn left in [x] meters.", Intent.LEFT, "turn_distance", distance=40.0,
                        maneuver_pos=50.0),
            Instruction(2, 30.0, "Turn left at the lights.", Intent.LEFT, "turn_traffic_light",
                        maneuver_pos=50.0),
            Instruction(3, 75.0, "Follow the road.", Intent.FOLLOW, "follow"))


def test_the_navigator_answers_the_maneuver_ahead_once_after_its_delay():
    nav = Navigator(MANEUVERS, BASELINE, delay=2.0)
    first = nav.ask(1.0, 0.0)                    # the lane change starts here
    assert (first.answered, first.instruction_id) == (True, 0)
    assert nav.shown(2.9, 0) is None             # the delay: the agent drives on meanwhile
    assert nav.shown(3.0, 0) == ("Move into the left lane.", 0)
    assert nav.shown(3.5, 0) == ("Move into the left lane.", 0)
    assert nav.shown(3.6, 1) is None             # shown until the next instruction is triggered
    # past the lane change's start the turn is ahead: the baseline's first words for it here
    assert nav.ask(4.0, 5.0).instruction_id == 1
    assert nav.ask(4.5, 6.0).answered is False   # the same maneuver: counted, not answered
    assert nav.shown(6.0, 1) == ("Turn left in 40 meters.", 1)
    assert nav.ask(9.0, 60.0).answered is False  # still in the junction
    last = nav.ask(20.0, 80.0)                   # nothing left: "Follow the road."
    assert (last.answered, last.instruction_id) == (True, -1)
    assert nav.shown(21.0, 3) is None and nav.shown(22.0, 3) == (FALLBACK_TEXT, -1)
    assert [(a.t, a.progress, a.answered) for a in nav.asks] == [
        (1.0, 0.0, True), (4.0, 5.0, True), (4.5, 6.0, False), (9.0, 60.0, False), (20.0, 80.0, True)]


def test_the_answer_is_in_the_words_the_baseline_uses_there():
    nav = Navigator(MANEUVERS, BASELINE)
    assert nav.ask(1.0, 35.0).instruction_id == 2   # the near announcement is the one shown at 35 m
    assert nav.wording(1, 12.0).id == 1 and nav.wording(1, 0.0).id == 1 and nav.wording(2, 0.0) is None
    assert ASK_DELAY == nav.delay == 2.0


def test_the_asking_option_is_a_bool(tmp_path):
    from icrsumo.evaluation import EvalOptions

    with pytest.raises(InputError, match="asking: 'yes': must be True or False"):
        EvalOptions(out=tmp_path / "o", asking="yes").check()
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- real episodes
@pytest.fixture(scope="module")
def routes(cache):
    """tiny_003 (a left turn at a T-junction) and tiny_013 (a left turn at a stop sign, announced
    twice) of the tiny suite: scenario and instruction sets (family, k) -> set."""
    from icrsumo.evaluation.bundled import bundled_route
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.world.scenario import read_scenario

    out = {}
    for rid in ("tiny_003", "tiny_013"):
        sc_dir, instr = bundled_route(rid)
        out[rid] = read_scenario(sc_dir), {(s.family, s.k): s for s in read_instruction_sets(instr)}
    return out


class _Seen(EpisodeCallback):
    """Every observation the agent got: (t, instruction, id, answer)."""

    def __init__(self) -> None:
        self.seen: list[tuple[float, str, int, bool]] = []

    def on_observation(self, episode, obs) -> None:
        self.seen.append((obs.t, obs.instruction, obs.instruction_id, obs.answer))


ASKING = RunOptions(asking=True)


@pytest.mark.sumo
def test_the_follower_asks_on_ambiguity_and_follows_the_plans_answer(routes):
    """tiny_003 ambiguity k=0 ("Make a turn up ahead."-like texts): without asking the follower
    cannot place the intent and leaves the route; with asking it asks at the first instruction,
    reads the baseline's own turn instruction 2 s later, and completes the route."""
    sc, sets = routes["tiny_003"]
    base, amb = sets[("baseline", 0)], sets[("ambiguity", 0)]
    off = run_episode(sc, amb, InstructionFollower(), baseline=base)
    assert off.asks == () and score_episode(off).termination_class.value == "RD"
    seen = _Seen()
    on = run_episode(sc, amb, InstructionFollower(), ASKING, callbacks=[seen], baseline=base)
    first = on.asks[0]
    turn = next(i for i in base.instructions if i.maneuver_pos is not None)
    assert (first.t, first.answered, first.instruction_id) == (seen.seen[0][0], True, turn.id)
    answers = [s for s in seen.seen if s[3]]
    assert answers[0][1:] == (turn.rendered(), turn.id, True)
    before = [s for s in seen.seen if s[0] < first.t + ASK_DELAY - 1e-9]
    assert before and not any(s[3] for s in before)         # nothing before the delay is over
    assert answers[0][0] >= first.t + ASK_DELAY - 1e-9
    r = score_episode(on)
    assert r.termination == "completed" and r.ds > score_episode(off).ds
    assert ask_counts(on) == (len(on.asks), sum(a.answered for a in on.asks))


@pytest.mark.sumo
def test_an_answered_turn_stands_for_the_next_unclear_instruction(routes):
    """tiny_013 announces its turn twice; both ambiguous. The follower asks once, and when the
    second unclear instruction comes before the junction it drives by the answer it holds instead
    of asking again (an ask the navigator would not answer)."""
    sc, sets = routes["tiny_013"]
    base, amb = sets[("baseline", 0)], sets[("ambiguity", 0)]
    log = run_episode(sc, amb, InstructionFollower(), ASKING, baseline=base)
    junction = next(i.maneuver_pos for i in base.instructions if i.maneuver_pos is not None)
    assert [a.progress < junction for a in log.asks].count(True) == 1 and log.asks[0].answered
    assert score_episode(log).termination == "completed"


class _AskEveryStep(RouteOracle):
    """The route-oracle (which ignores the instruction) asking at every decision."""

    name = "route-oracle"

    def act(self, obs):
        self.decisions = getattr(self, "decisions", 0) + 1
        return replace(super().act(obs), ask=True)


@pytest.mark.sumo
def test_an_agent_asking_at_every_step_is_answered_once_per_maneuver_and_every_ask_counts(routes):
    from icrsumo.instructions.maneuvers import extract_maneuvers
    from icrsumo.world.networks import load_net

    sc, sets = routes["tiny_003"]
    base, amb = sets[("baseline", 0)], sets[("ambiguity", 3)]
    agent = _AskEveryStep()
    log = run_episode(sc, amb, agent, ASKING, baseline=base)
    assert len(log.asks) == agent.decisions > 50             # every ask is stored
    nav = Navigator(extract_maneuvers(sc, load_net(sc.net)), base.instructions)
    answered = [nav.ahead(a.progress) for a in log.asks if a.answered]
    assert answered == sorted(set(answered)) == list(range(len(nav.maneuvers) + 1))  # once per maneuver
    # the asks change nothing else: the oracle drives as without them
    plain = run_episode(sc, amb, RouteOracle(), baseline=base)
    assert dumps_log(replace(log, asks=())) == dumps_log(plain)
    # asking off: the asks are ignored and the log is byte-identical to the plain oracle's
    assert dumps_log(run_episode(sc, amb, _AskEveryStep(), baseline=base)) == dumps_log(plain)


@pytest.mark.sumo
def test_with_asking_on_an_agent_that_does_not_ask_gives_the_same_log(routes):
    sc, sets = routes["tiny_003"]
    base = sets[("baseline", 0)]
    off = run_episode(sc, base, InstructionFollower())
    on = run_episode(sc, base, InstructionFollower(), ASKING)   # the baseline is clear: no ask
    assert on.asks == () and dumps_log(on) == dumps_log(off) and '"asks"' not in dumps_log(on)


class _BadAsk(RouteOracle):
    def act(self, obs):
        return replace(super().act(obs), ask="yes")


@pytest.mark.sumo
def test_bad_asking_input_is_named(routes):
    sc, sets = routes["tiny_003"]
    with pytest.raises(InputError, match="baseline.*asking needs the route's baseline instructions"):
        run_episode(sc, sets[("ambiguity", 0)], RouteOracle(), ASKING)
    with pytest.raises(InputError, match="baseline"):
        run_episode(sc, sets[("ambiguity", 0)], RouteOracle(), ASKING, baseline=sets[("paraphrase", 0)])
    with pytest.raises(AgentError, match="Action.ask must be True or False, got 'yes'"):
        run_episode(sc, sets[("baseline", 0)], _BadAsk(), ASKING)
    assert Action(waypoints=np.zeros((1, 2))).ask is False


@pytest.mark.sumo
def test_evaluate_asking_stores_and_counts_asks_and_is_part_of_the_configuration(suite, tmp_path):
    """``icrsumo evaluate --asking`` (a real subprocess): the instruction-follower's ambiguity
    episode asks, its row counts the asks, its log holds them; the baseline asks nothing;
    summary.json and results.md show the ask rate; the folder cannot be resumed without
    --asking (one line, exit status 2)."""
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "icrsumo", "evaluate", "--suite", str(suite), "--agent",
           "instruction-follower", "--family", "ambiguity", "--k", "1", "--workers", "1", "--quiet",
           "--out", str(out)]
    proc = subprocess.run([*cmd, "--asking"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert json.loads((out / "config.json").read_text())["asking"] is True
    with sqlite3.connect(out / "results.sqlite") as c:
        rows = dict(c.execute("SELECT family, asks FROM episodes").fetchall())
        answered = c.execute("SELECT asks_answered FROM episodes WHERE family = 'ambiguity'").fetchone()[0]
    assert rows["baseline"] == 0 and rows["ambiguity"] >= answered >= 1
    stats = Summary.read(out / "summary.json").agents["instruction-follower"]
    amb = stats.families["ambiguity"].asking
    assert (amb.ask_rate, amb.asks, amb.asks_answered) == (1.0, rows["ambiguity"], answered)
    assert stats.baseline.asking.ask_rate == 0.0
    md = (out / "results.md").read_text(encoding="utf-8")
    header = [c.strip() for c in md.splitlines()[0].strip("|").split("|")]
    row = next(line for line in md.splitlines() if line.startswith("| instruction-follower | ambiguity |"))
    assert [c.strip() for c in row.strip("|").split("|")][header.index("ask %")] == "100.0"
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    line = again.stderr.strip()
    assert again.returncode == 2 and "\n" not in line and "asking" in line and "--asking" in line
