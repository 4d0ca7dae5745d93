"""``icrsumo show``: watch any stored episode. Re-simulates it from its out folder (scenario,
instruction sequence, agent, seed), checks that the replay reproduces the stored log byte for
byte, and writes the BEV video (WebM: it plays in a browser) with the active instruction and
notices overlaid plus a still of the moment the episode went wrong: the decision at which it left
its route or its first infraction, whichever came first, else where it ended."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from icrsumo.agents.base import Observation
from icrsumo.core.errors import Field, InputError
from icrsumo.core.fsio import bounded_name
from icrsumo.core.types import EpisodeLog, EpisodeRecord
from icrsumo.core.vocab import DecisionOutcome, EpisodeStatus, Family, Intent
from icrsumo.results.decisions import Decision, divergence
from icrsumo.results.store import ResultStore
from icrsumo.sim.callbacks import EpisodeCallback
from icrsumo.world.convert import safe_name


@dataclass(frozen=True)
class ShowResult:
    """What :func:`show_episode` wrote and found. ``video`` and ``still``: the files;
    ``moment_t`` (s) and ``moment``: when and why the still was taken; ``identical``: the
    replay's log equals the stored one byte for byte, else ``difference`` says where it first
    differs; ``record``: the stored episode."""

    record: EpisodeRecord
    video: Path
    still: Path
    moment_t: float
    moment: str
    identical: bool
    difference: str = ""


def reached_step(progress: Sequence[float], pos: float) -> int:
    """The step at which the ego reached route position ``pos`` (m): the first step at or past
    it, else the first at its farthest progress (it left the route before getting there)."""
    target = min(pos, max(progress))
    return next(i for i, p in enumerate(progress) if p >= target)


def failure_moment(log: EpisodeLog, scoring: str, decisions: Sequence[Decision] = ()) -> tuple[float, str]:
    """When (s) and why an episode went wrong: the earlier of its first penalised infraction
    and the decision at which it left its route (``decisions``: the episode's, from
    :func:`icrsumo.results.decisions.classify_decisions`), taken when the ego reached that junction or
    lane change, where the branch is chosen; else its termination (for a completed episode
    without infractions: its end)."""
    from icrsumo.scoring import score_episode

    moments = []
    result = score_episode(log, scoring)
    if result.infractions:
        first = min(result.infractions, key=lambda i: i.t)
        other = f" with {first.other}" if first.other else ""
        moments.append((first.t, f"{first.kind}{other} at {first.pos:.0f} m along the route"))
    left = divergence(decisions)
    if left is not None and left.outcome in (DecisionOutcome.FOLLOWED_TEXT, DecisionOutcome.OTHER) and log.t:
        said = ("the instruction named no branch" if left.text_intent == Intent.UNKNOWN
                else f"the instruction said {left.text_intent}")
        moments.append((log.t[reached_step(log.progress, left.pos)],
                        f"the decision where it left the route: {left.kind} at {left.pos:.0f} m, the route "
                        f"goes {left.route_intent}, {said}, it went {left.executed}"))
    if moments:
        return min(moments, key=lambda m: m[0])
    end = log.t[-1] if log.t else log.termination_t
    where = f" at {log.progress[-1]:.0f} m of {log.route_length:.0f} m" if log.progress else ""
    return end, f"{result.termination}{where}"


def first_difference(a: EpisodeLog, b: EpisodeLog) -> str:
    """Where two logs of one episode first differ, in words ("" when the compared fields agree)."""
    for col in ("t", "x", "y", "yaw", "speed", "progress", "instruction"):
        xa, xb = getattr(a, col), getattr(b, col)
        for i, (u, v) in enumerate(zip(xa, xb)):
            if u != v:
                t = a.t[i] if i < len(a.t) else float("nan")
                return f"{col} first differs at step {i} (t = {t:.1f} s: {u!r} stored, {v!r} now)"
        if len(xa) != len(xb):
            return f"the stored log has {len(xa)} steps, the replay {len(xb)}"
    if a.termination != b.termination:
        return f"the termination differs ({a.termination} stored, {b.termination} now)"
    return "the event lists or the scores' inputs differ"


class _Recorder(EpisodeCallback):
    """Writes the video and keeps the frame of the last observation at or before ``moment_t``."""

    def __init__(self, video: Path, moment_t: float) -> None:
        from icrsumo.render import VideoWriter

        self.writer = VideoWriter(video)
        self.moment_t = moment_t
        self.still: np.ndarray | None = None

    def on_observation(self, episode, obs: Observation) -> None:
        self.writer.add(obs.bev, obs.instruction, obs.notice, obs.speed, obs.t)
        if self.still is None or obs.t <= self.moment_t + 1e-9:
            self.still = self.writer.frame(obs.bev, obs.instruction, obs.notice, obs.speed, obs.t)

    def on_close(self, episode) -> None:
        self.writer.close()


def _find(store: ResultStore, agent: str, route: str, family: str, k: int, seed: int) -> EpisodeRecord:
    recs = [r for r in store.records() if r.seed == seed]
    for r in recs:
        if (r.agent, r.route_id, str(r.family), r.k) == (agent, route, family, k):
            return r
    if not recs:
        raise InputError(store.path, "", "holds no episodes", "run icrsumo evaluate into this folder first")
    for what, have, value in ((Field("agent"), {r.agent for r in recs}, agent),
                              (Field("route"), {r.route_id for r in recs}, route),
                              (Field("family"), {str(r.family) for r in recs}, family)):
        if value not in have:
            shown = ", ".join(sorted(have)[:8]) + (", ..." if len(have) > 8 else "")
            raise InputError(what, value, "no stored episode has it", f"use one of {shown}")
    ks = sorted({r.k for r in recs if (r.agent, r.route_id, str(r.family)) == (agent, route, family)})
    raise InputError(Field("k"), str(k), f"no stored episode of {agent} on {route} in {family} has it",
                     f"use one of {', '.join(map(str, ks))}" if ks else "pick another family or route")


def _instructions(out: Path, rec: EpisodeRecord) -> Path:
    if rec.family == Family.ATTACK:
        from icrsumo.evaluation.attack import agent_folder

        found = sorted((out / "attack").glob(f"*/{agent_folder(rec.agent)}/{safe_name(rec.route_id)}.json"))
        if found:
            return found[0]
    path = out / "instructions" / f"{safe_name(rec.route_id)}.json"
    if not path.is_file():
        raise InputError(path, "", "the episode's instruction file is missing",
                         "restore the out folder's instructions/ (icrsumo evaluate writes them)")
    return path


def _scenario(out: Path, cfg: dict, route: str):
    from icrsumo.world.scenario import find_scenarios, read_scenario

    root = out / "scenarios" if (out / "scenarios").is_dir() else Path(cfg["suite"])
    guess = root / "scenarios" / safe_name(route)
    if (guess / "scenario.json").is_file():
        sc = read_scenario(guess)
        if sc.route_id == route:
            return sc
    if (root / "index.json").is_file():
        for d in find_scenarios(root):
            sc = read_scenario(d)
            if sc.route_id == route:
                return sc
    raise InputError(root, route, "the episode's scenario is missing",
                     "restore the out folder's scenarios/ (icrsumo evaluate converts them there)")


def show_episode(out: Path, agent: str, route: str, family: str, k: int, dest: Path | None = None,
                 spec: str | None = None) -> ShowResult:
    """Re-simulate one stored episode of the evaluation folder ``out`` (a crashed one up to its
    crash, where its log up to it was stored) and write
    ``dest/episode.webm`` (:class:`icrsumo.render.VideoWriter`: another container only where
    this OpenCV cannot write VP8) and ``dest/moment.png`` (:func:`failure_moment`)
    (default ``dest``: ``OUT/show/AGENT_ROUTE_FAMILY_K``). ``agent`` is the stored name; the
    agent is rebuilt from the spec the folder's configuration records for it (``spec``
    overrides: for folders written before icrsumo recorded specs)."""
    from icrsumo.agents.identity import fingerprint, short
    from icrsumo.agents.registry import PYTHON_PREFIX, agent_factory
    from icrsumo.evaluation.run import bind_agents, read_config
    from icrsumo.guards.base import guarded_fingerprint
    from icrsumo.instructions.store import read_route_file
    from icrsumo.render import write_image
    from icrsumo.results.decisions import classify_decisions
    from icrsumo.results.logs import dumps_log, loads_log
    from icrsumo.sim.episode import RunOptions, drive_episode

    out = Path(out)
    cfg = read_config(out)
    scoring = str(cfg.get("scoring") or "lb1")
    with ResultStore(out / "results.sqlite", readonly=True) as store:  # a read-only folder is fine
        rec = _find(store, agent, route, family, k, int(cfg["seed"]))
        stored_text = store.log(rec.agent, rec.route_id, rec.family, rec.k, rec.seed)
        if rec.status != EpisodeStatus.DONE and stored_text is None:
            raise InputError(out / "results.sqlite", f"episode {agent}/{route}/{family}/{k}",
                             f"crashed before its first step ({rec.message[:120]}), so it has no log "
                             "to replay",
                             "rerun it with icrsumo evaluate --retry-crashed, then show it")
        stored_fp = store.episode_fingerprint(rec.agent, rec.route_id, rec.family, rec.k, rec.seed)
    if stored_text is None:
        raise InputError(out / "results.sqlite", f"episode {agent}/{route}/{family}/{k}", "has no stored log",
                         f"run it again into another {Field('out')} folder")
    stored = loads_log(stored_text)
    entry = (cfg.get("agents") or {}).get(agent)
    spec = spec or (entry.get("spec") if isinstance(entry, dict) else None) or agent
    if spec.startswith(PYTHON_PREFIX):
        raise InputError(Field("agent"), agent, f"was given to the Python API as an object ({spec}), which "
                         "cannot be rebuilt from its name",
                         f"pass {Field('spec')} module:Class (or path/file.py:Class)")
    factory = agent_factory(spec)
    fp = fingerprint(factory)
    factory = bind_agents({spec: factory}, out)[spec]  # an LLM agent: answered from OUT/llm-cache
    guard = entry.get("guard") if isinstance(entry, dict) else None
    guards = _guards(guard, out) if isinstance(guard, str) and guard else None
    on_block = str(entry.get("on_block") or "keep") if guards is not None else "keep"
    if guards is not None:  # a guarded row: its fingerprint covers the guard and its policy (evaluation.run)
        fp = guarded_fingerprint(fp, fingerprint(guards[0]), on_block)
    if stored_fp and fp != stored_fp:
        raise InputError(Field("agent"), agent,
                         f"the agent {spec} is now another agent (fingerprint {short(fp)}, "
                         f"stored {short(stored_fp)}): the replay would not be the stored episode",
                         "restore the agent's code or checkpoint as it was")
    sc = _scenario(out, cfg, route)
    instr_file = _instructions(out, rec)
    route_sets, maneuvers = read_route_file(instr_file)
    sets = {(s.family, s.k): s for s in route_sets}
    iset = sets.get((rec.family, rec.k))
    if iset is None:
        raise InputError(instr_file, f"{family} k={k}", "the instruction sequence is missing",
                         "restore the out folder's instruction files")
    moment_t, moment = failure_moment(stored, scoring, classify_decisions(maneuvers, iset, stored))
    dest = Path(dest) if dest is not None else out / "show" / bounded_name(
        safe_name(f"{agent}_{route}_{family}_{k}"))
    try:
        dest.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(dest, "", f"cannot be made for the video and still ({err.strerror or err})",
                         "give a folder you can write to for them (dest)") from None
    recorder = _Recorder(dest / "episode.webm", moment_t)
    # a crashed episode stored with its log up to the crash is replayed up to the crash again
    log, _ = drive_episode(sc, iset, factory(), RunOptions(scoring=scoring, asking=cfg.get("asking") is True,
                                                           on_block=on_block),
                           callbacks=[recorder], guard=guards[1]() if guards is not None else None,
                           baseline=sets.get(("baseline", 0)))
    still = dest / "moment.png"
    if recorder.still is not None:
        write_image(still, recorder.still, f"t = {moment_t:.1f} s: {moment}")
    text = dumps_log(log)
    identical = text == stored_text
    return ShowResult(rec, recorder.writer.path, still, moment_t, moment, identical,
                      "" if identical else first_difference(stored, loads_log(text)))


def _guards(spec: str, out: Path) -> tuple:
    """(factory, factory bound to ``out``) of a guarded row's guard ``spec`` (an LLM guard
    answers from OUT/llm-cache; the others are the same factory twice)."""
    from icrsumo.evaluation.run import bind_guards
    from icrsumo.guards.registry import guard_factory

    factory = guard_factory(spec)
    return factory, bind_guards({spec: factory}, out).get(spec, factory)
