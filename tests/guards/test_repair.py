"""Repair instead of refusal (issue 46): the ``navigator`` block policy shows the navigation
plan's own instruction, in the route's baseline words, where a guard blocks one; a guard may
repair an instruction itself (the third verdict), and a repair that cannot be placed on the plan,
a repaired text with a pass, or a repair without a text crashes the episode with one line naming
the guard. The stream on its own with the real ``plan`` guard on tiny_003 (a left turn at a
T-junction), then real SUMO episodes of the instruction-follower, evaluations and the command
line."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys

import pytest

import icrsumo
from icrsumo.agents.privileged import InstructionFollower
from icrsumo.core.errors import InputError
from icrsumo.core.types import Intent
from icrsumo.core.vocab import Verdict
from icrsumo.guards.base import (
    FALLBACK_TEXT,
    GuardError,
    Ruling,
    guarded_name,
    ruling_of,
    split_policy,
    split_row,
    verdict_of,
)
from icrsumo.guards.plan import PlanGuard
from icrsumo.guards.registry import GUARDS
from icrsumo.guards.stream import GuardedStream
from icrsumo.results.logs import dumps_log, loads_log
from icrsumo.results.store import ResultStore
from icrsumo.scoring import score_episode
from icrsumo.sim.callbacks import EpisodeCallback
from icrsumo.sim.episode import RunOptions, run_episode
from icrsumo.world.networks import load_net

#: SHA-256 of the log of tiny_003 misleading k=0, the instruction-follower behind ``plan``, as
#: icrsumo wrote it before block policies existed: ``keep`` must leave it byte for byte
KEEP_LOG_SHA256 = "51c13e3cc774e3929021f574e112b80dc875ea2a18a70bb9c6b8698265cf8da4"
ROW = "instruction-follower+guard:plan"


# --------------------------------------------------------------------------- guards that repair
class Repairing:
    """Repairs every instruction with the plan's next turn ("Turn left.") or, with no junction
    maneuver ahead, "Follow the road.": a guard using the protocol's third verdict."""

    name, needs_plan = "repairing", True

    def reset(self, info):
        pass

    def words(self, intent: Intent) -> str:
        return f"Turn {intent}."

    def check(self, text, context):
        step = context.plan.next_junction()
        return Verdict.REPAIR, "rewritten from the plan", \
            self.words(step.intent) if step is not None else "Follow the road."


class Misplaced(Repairing):
    """Repairs with the turn the plan does not take: cannot be placed on it."""

    name = "misplaced"

    def words(self, intent: Intent) -> str:
        return "Turn right." if intent is Intent.LEFT else "Turn left."


class PassWithText(Repairing):
    """Passes an instruction and hands a repaired text with it."""

    name = "passtext"

    def check(self, text, context):
        return Verdict.PASS, "", "Turn left."


class Textless(Repairing):
    """Answers a repair without the repaired text."""

    name = "textless"

    def check(self, text, context):
        return Verdict.REPAIR, "no text"


# --------------------------------------------------------------------------- the protocol
def test_a_guard_may_repair_and_a_bad_repair_is_a_guard_error_naming_it():
    repair = Ruling(Verdict.REPAIR, "why", "Turn left.")
    assert ruling_of((Verdict.REPAIR, " why\n", "Turn left."), "g") == repair
    assert ruling_of(("repair", "", "Turn left."), "g").verdict is Verdict.REPAIR
    assert ruling_of((Verdict.PASS, "ok", ""), "g") == Ruling(Verdict.PASS, "ok")
    assert verdict_of((Verdict.BLOCK, "no"), "g") == (Verdict.BLOCK, "no")   # the pair as before
    for answer, why in [((Verdict.REPAIR, "r"), "a repair without the repaired text"),
                        (Verdict.REPAIR, "a repair without the repaired text"),
                        ((Verdict.REPAIR, "r", "  "), "a repair without the repaired text"),
                        ((Verdict.PASS, "", "Turn left."), "a repaired text with pass"),
                        ((Verdict.BLOCK, "", "Turn left."), "a repaired text with block"),
                        ((Verdict.REPAIR, "r", 3), "returned 3, not pass / block / repair")]:
        with pytest.raises(GuardError, match=f"^guard mine .*{why}") as err:
            ruling_of(answer, "mine")
        assert "\n" not in str(err.value)


def test_the_policy_is_in_the_row_name():
    row = guarded_name("a", "plan", "navigator")
    assert row == "a+guard:plan+navigator" and guarded_name("a", "plan") == guarded_name("a", "plan", "keep")
    assert split_row(row) == ("a", "plan+navigator")
    assert split_policy("plan+navigator") == ("plan", "navigator")
    assert split_policy("plan") == ("plan", "keep") and split_policy("+navigator") == ("+navigator", "keep")


# --------------------------------------------------------------------------- the stream, no episode
@pytest.fixture(scope="module")
def route(cache):
    """tiny_003: its scenario, road network and instruction sets (family, k) -> set."""
    from icrsumo.evaluation.bundled import bundled_route
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.world.scenario import read_scenario

    sc_dir, instr = bundled_route("tiny_003")
    sc = read_scenario(sc_dir)
    return sc, load_net(sc.net), {(s.family, s.k): s for s in read_instruction_sets(instr)}


def _stream(route, guard, on_block="keep", family=("misleading", 0)):
    sc, net, sets = route
    ins = sets[family].instructions
    return GuardedStream(guard, sc, net, ins, [i.rendered() for i in ins], on_block,
                         sets[("baseline", 0)].instructions if on_block == "navigator" else None)


def _drive(stream):
    """Both instructions of tiny_003 as they become active (the turn's, then the follow one past
    the junction); what the agent read after each."""
    seen = []
    for k, (t, progress) in enumerate([(20.05, 0.0), (27.05, 43.94)]):
        stream.shown(k, t, progress)
        seen.append(stream.observed())
    return seen


def test_the_navigator_policy_shows_the_baselines_words_where_the_plan_guard_blocks(route):
    base = route[2][("baseline", 0)].instructions
    nav = _stream(route, PlanGuard(), "navigator")
    assert _drive(nav) == [(base[0].rendered(), base[0].id), (FALLBACK_TEXT, 1)]
    turn, follow = nav.decisions
    assert (turn.verdict, turn.text, turn.baseline_id) == (Verdict.REPAIR, "At the T-junction, turn left.", 0)
    assert turn.reason == "right, but the plan goes left in 24 m"         # the guard's own reason
    assert (follow.verdict, follow.text, follow.baseline_id) == (Verdict.REPAIR, FALLBACK_TEXT, -1)
    assert nav.current == -1                      # the log shows no text of the family
    # keep: today's behaviour, the fallback and plain blocks
    keep = _stream(route, PlanGuard())
    assert _drive(keep) == [(FALLBACK_TEXT, -1), (FALLBACK_TEXT, -1)]
    assert [(d.verdict, d.text, d.baseline_id) for d in keep.decisions] == [(Verdict.BLOCK, "", -1)] * 2
    # what passes is shown as written under either policy
    plain = _stream(route, PlanGuard(), "navigator", ("baseline", 0))
    assert _drive(plain) == [(b.rendered(), b.id) for b in base]


def test_a_guards_own_repair_is_shown_and_one_off_the_plan_is_refused(route):
    own = _stream(route, Repairing())
    assert _drive(own) == [("Turn left.", 0), ("Follow the road.", 1)]
    assert [(d.verdict, d.text, d.baseline_id) for d in own.decisions] == [
        (Verdict.REPAIR, "Turn left.", -1), (Verdict.REPAIR, "Follow the road.", -1)]
    with pytest.raises(GuardError, match=r"^guard misplaced repaired instruction 0 as 'Turn right.', which "
                                         r"reads as right, not the plan's left there"):
        _drive(_stream(route, Misplaced(), "navigator"))


def test_the_policy_is_checked_and_the_navigator_needs_the_baseline(route):
    sc, net, sets = route
    ins = sets[("misleading", 0)].instructions
    with pytest.raises(InputError, match="^on_block: 'nope': unknown block policy .*use keep or navigator"):
        GuardedStream(PlanGuard(), sc, net, ins, [i.text for i in ins], "nope")
    with pytest.raises(InputError, match="^baseline: tiny_003: the navigator block policy needs"):
        GuardedStream(PlanGuard(), sc, net, ins, [i.text for i in ins], "navigator")
    with pytest.raises(InputError, match="^baseline: tiny_003: the navigator block policy needs"):
        run_episode(sc, sets[("misleading", 0)], InstructionFollower(), RunOptions(on_block="navigator"),
                    guard=PlanGuard())


# --------------------------------------------------------------------------- real episodes
class _Read(EpisodeCallback):
    """Every instruction text the agent read."""

    def __init__(self) -> None:
        self.texts: set[str] = set()

    def on_observation(self, episode, obs) -> None:
        self.texts.add(obs.instruction)


def test_the_follower_completes_the_route_with_the_repair_and_fails_with_keep(route):
    """tiny_003 misleading k=0 tells of a right turn where the route turns left: ``plan``
    blocks it; with ``keep`` the follower reads "Follow the road." and leaves the route at the
    T-junction (the very log of before block policies existed), with ``navigator`` it reads the
    baseline's "At the T-junction, turn left." and completes it."""
    sc, _, sets = route
    mis, base = sets[("misleading", 0)], sets[("baseline", 0)]
    keep = run_episode(sc, mis, InstructionFollower(), guard=PlanGuard(), baseline=base)
    assert hashlib.sha256(dumps_log(keep).encode()).hexdigest() == KEEP_LOG_SHA256
    assert score_episode(keep).termination_class.value == "RD"
    read = _Read()
    nav = run_episode(sc, mis, InstructionFollower(), RunOptions(on_block="navigator"), callbacks=[read],
                      guard=PlanGuard(), baseline=base)
    assert nav.agent == f"{ROW}+navigator" and score_episode(nav).termination_class.value == "done"
    assert "At the T-junction, turn left." in read.texts
    assert not read.texts & {i.rendered() for i in mis.instructions}
    assert [d.verdict for d in nav.guard] == [Verdict.REPAIR] * 2 and set(nav.instruction) == {-1}
    d = json.loads(dumps_log(nav))["guard"][0]
    assert d == {"t": 20.05, "progress": 0.0, "instruction_id": 0, "verdict": "repair",
                 "reason": "right, but the plan goes left in 24 m", "text": "At the T-junction, turn left.",
                 "baseline_id": 0}
    assert loads_log(dumps_log(nav)).guard == nav.guard           # repairs round-trip


def test_bad_repairs_crash_their_episodes_with_one_line_naming_the_guard(suite, tmp_path):
    bad = {"misplaced": "guard misplaced repaired instruction 0 as 'Turn right.', which reads as right",
           "passtext": "guard passtext returned a repaired text with pass",
           "textless": "guard textless returned a repair without the repaired text"}
    guards = (Repairing, Misplaced, PassWithText, Textless)
    for guard in guards:
        GUARDS.register(guard.name, guard)
    try:
        res = icrsumo.evaluate(suite=str(suite), agents="instruction-follower",
                               guards=[g.name for g in guards], families="misleading", k=1,
                               out=tmp_path / "o", workers=1, agent_timeout=None)
    finally:
        for guard in guards:
            GUARDS.unregister(guard.name)
    with ResultStore(tmp_path / "o" / "results.sqlite") as store:
        records = store.records()
    crashed = [r for r in records if r.status == "crashed"]
    assert res.crashed == len(crashed) == 6 and res.done == 4   # baseline + misleading, 3 guards
    for r in crashed:
        guard = r.agent.rpartition("+guard:")[2]
        assert bad[guard] in r.message and "\n" not in r.message
    own = {r.family: r for r in records if r.agent == "instruction-follower+guard:repairing"}
    assert own["misleading"].termination_class == "done"
    assert (own["misleading"].guard_repaired, own["misleading"].guard_blocked) == (2, 2)
    doc = json.loads((tmp_path / "o" / "guard.json").read_text())
    row = doc["rows"]["instruction-follower+guard:repairing"]
    assert row["on_block"] == "keep" and row["families"]["misleading"]["repairs"]["repaired"] == 2
    assert doc["guards"]["repairing"]["repaired"] == {"baseline": 2, "misleading": 2}


# --------------------------------------------------------------------------- the command line
def _evaluate(out, *more):
    return subprocess.run([sys.executable, "-m", "icrsumo", "evaluate", "--agent", "instruction-follower",
                           "--family", "misleading", "--k", "1", "--workers", "1", "--quiet",
                           "--out", str(out), *more], capture_output=True, text=True, timeout=600)


def test_the_on_block_flag_its_rows_reports_and_the_folder_it_binds(suite, tmp_path):
    out = tmp_path / "o"
    p = _evaluate(out, "--suite", str(suite), "--guard", "plan", "--on-block", "navigator")
    assert p.returncode == 0, p.stderr[-2000:]
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["on_block"] == "navigator" and cfg["agents"][f"{ROW}+navigator"]["on_block"] == "navigator"
    doc = json.loads((out / "guard.json").read_text())
    mis = doc["rows"][f"{ROW}+navigator"]["families"]["misleading"]
    assert mis["blocked"] == mis["checked"] == 2 and mis["guarded"]["DS"] == 100.0 > mis["unguarded"]["DS"]
    assert mis["repairs"] == {"repaired": 2, "episodes": 1, "pairs": 1, "DS": 100.0,
                              "DS_unguarded": mis["unguarded"]["DS"], "RC": 100.0,
                              "RC_unguarded": mis["unguarded"]["RC"]}
    md = (out / "guard.md").read_text()
    assert "| misleading | 2/2 (100.0 %) |" in md and "| 2 in 1 episodes | 100.0 / " in md
    # icrsumo show replays a repaired episode under its policy: the very stored log
    from icrsumo.app.show import show_episode

    assert show_episode(out, f"{ROW}+navigator", "tiny_003", "misleading", 0, tmp_path / "show").identical
    # the other policy is refused on the folder, in one line, before anything is written
    before = (out / "results.sqlite").read_bytes()
    again = _evaluate(out, "--suite", str(suite), "--guard", "plan")
    assert again.returncode == 2 and len(again.stderr.strip().splitlines()) == 1
    assert "on_block='navigator' (now 'keep')" in again.stderr and "--on-block navigator" in again.stderr
    assert "Traceback" not in again.stderr and (out / "results.sqlite").read_bytes() == before
    # the navigator policy without a guard has nothing to repair
    lone = _evaluate(tmp_path / "lone", "--suite", str(suite), "--on-block", "navigator")
    assert lone.returncode == 2 and lone.stderr.strip().splitlines() == [
        "icrsumo: error: --on-block: navigator: applies to guarded rows, and no guard is given (fix: add "
        "--guard NAME, or leave --on-block out)"]
    assert not (tmp_path / "lone").exists()


def test_attack_takes_the_policy_too(suite, tmp_path):
    from icrsumo.evaluation.attack import AttackOptions, run_attack

    doc = run_attack(AttackOptions(out=tmp_path / "a", suite=str(suite), agents=("instruction-follower",),
                                   guards=("plan",), on_block="navigator", budget=1))
    assert set(doc["agents"]) == {"instruction-follower", f"{ROW}+navigator"}


def test_the_option_is_checked_before_anything_is_written(tmp_path):
    from icrsumo.evaluation import EvalOptions

    for value, why in [("nope", "on_block: 'nope': unknown block policy"),
                       (3, "on_block: 3: must be a string")]:
        with pytest.raises(InputError, match=f"^{why}"):
            EvalOptions(out=tmp_path / "o", guards=("plan",), on_block=value).check()
    assert not (tmp_path / "o").exists()
