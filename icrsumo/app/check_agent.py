"""``icrsumo check-agent SPEC``: does an agent follow the protocol? Plain-words findings.

Loads the spec, checks the protocol's members (``reset``, ``act``, ``name``, ``privileged``),
then drives two episodes of a short bundled scenario (tiny_003 by default: 78 m, one left
turn, cached like the Gymnasium environment's) with two fresh instances and the same
EpisodeInfo (same seed), each for at most ``max_decisions`` decisions. Every action is checked
as ``icrsumo evaluate`` checks it (type, shape, NaN); exceptions are reported with their place;
a call that takes longer than ``timeout`` s is reported as a hang; the two runs' actions must be
identical (a fixed seed gives a fixed episode); the mean time per ``act`` must stay under
``max_act_ms``; and an ``act_batch`` hook, if present, must return what ``act`` returns.
Agent calls run on a helper thread (SUMO stays on the calling thread), so a hung agent is left
behind on that thread and the check still ends.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from icrsumo.agents.base import Action, AgentError, AgentTimeout, Observation, batch_hook, validate_action
from icrsumo.agents.hosting.watch import ThreadWatch
from icrsumo.agents.registry import BUILTIN, LLM_PREFIX, REMOTE_PREFIX, agent_factory, load_class
from icrsumo.core.errors import Field, InputError, describe
from icrsumo.evaluation.bundled import DEFAULT_ROUTE, DEFAULT_SUITE, bundled_route

#: decisions per run (0.1 s each)
MAX_DECISIONS = 300
#: default budget (ms) of one act() call: the control period, i.e. real time
MAX_ACT_MS = 100.0
#: episodes of the default ``icrsumo evaluate`` run, for the time estimate
DEFAULT_RUN_EPISODES = 528


@dataclass(frozen=True)
class Finding:
    """One line of the report: ``ok`` False for a problem, None for a note."""

    ok: bool | None
    text: str


@dataclass(frozen=True)
class CheckReport:
    """Every finding of one check, in order."""

    spec: str
    route: str
    findings: tuple[Finding, ...]

    @property
    def problems(self) -> list[str]:
        return [f.text for f in self.findings if f.ok is False]


def _timed(watch: ThreadWatch, fn: Callable, *args: Any) -> tuple[Any, float]:
    """(result, seconds) of one watched call; AgentTimeout when it hangs."""
    return watch.call(fn, *args), watch.last_s


def _raised(what: str, err: BaseException) -> str:
    return f"{what} raised {describe(err)}"


def _same(a: Action, b: Action) -> bool:
    if (a.control is None) != (b.control is None) or (a.waypoints is None) != (b.waypoints is None):
        return False
    if a.control is not None:
        return a.control == b.control
    wa, wb = np.asarray(a.waypoints), np.asarray(b.waypoints)
    return wa.shape == wb.shape and bool(np.array_equal(wa, wb)) and a.target_speed == b.target_speed


def _show(a: Action) -> str:
    if a.control is not None:
        c = a.control
        return f"control(steer={c.steer:.4g}, throttle={c.throttle:.4g}, brake={c.brake:.4g})"
    w = np.round(np.asarray(a.waypoints, dtype=float), 3).tolist()
    return f"waypoints {w[:3]}{' ...' if len(w) > 3 else ''}, target_speed {a.target_speed}"


@dataclass
class _Run:
    actions: list[Action]
    observations: list[Observation]
    act_s: list[float]
    problem: str = ""
    hung: bool = False
    termination: str = ""
    info: Any = None


def _drive(factory: Callable, caller: ThreadWatch, scenario, iset, timeout: float, max_decisions: int,
           keep_obs: int) -> _Run:
    from icrsumo.sim.episode import Episode

    run = _Run([], [], [])
    try:
        agent, _ = _timed(caller, factory)
    except AgentTimeout:
        run.problem, run.hung = f"creating the agent did not finish within {timeout:g} s", True
        return run
    except (Exception, SystemExit) as err:
        run.problem = _raised("creating the agent", err)
        return run
    privileged = bool(getattr(agent, "privileged", False))
    needs_route = bool(getattr(agent, "needs_route", False))
    with Episode(scenario, iset, privileged=privileged, needs_route=needs_route) as ep:
        run.info = ep.info
        try:
            _timed(caller, agent.reset, ep.info)
        except AgentTimeout:
            run.problem, run.hung = f"reset() did not answer within {timeout:g} s", True
            return run
        except (Exception, SystemExit) as err:
            run.problem = _raised("reset(info)", err)
            return run
        obs = ep.start()
        while obs is not None and len(run.actions) < max_decisions:
            n = len(run.actions) + 1
            at = f"act() at decision {n} (t = {obs.t:.2f} s)"
            try:
                action, dt = _timed(caller, agent.act, obs)
            except AgentTimeout:
                run.problem, run.hung = f"{at} did not answer within {timeout:g} s", True
                break
            except (Exception, SystemExit) as err:
                run.problem = _raised(at, err)
                break
            run.act_s.append(dt)
            try:
                action = validate_action(action)
            except AgentError as err:
                run.problem = f"{at} returned a broken action: {err}"
                break
            run.actions.append(action)
            if len(run.observations) < keep_obs:
                run.observations.append(obs)
            obs = ep.step(action)
        run.termination = ep.termination if ep.done else f"stopped after {len(run.actions)} decisions"
    if callable(getattr(agent, "close", None)):
        try:
            _timed(caller, agent.close)
        except (Exception, SystemExit) as err:  # noqa: BLE001 - reported, never fatal
            if not run.problem:
                run.problem = "close() did not answer" if isinstance(err, AgentTimeout) else \
                    _raised("close()", err)
    return run


def _check_limits(timeout: float, max_act_ms: float, max_decisions: int) -> None:
    """InputError unless the time limits are positive numbers and ``max_decisions`` at least 1."""
    for option, value in ((Field("timeout"), timeout), (Field("max_act_ms"), max_act_ms)):
        if not 0 < value < float("inf"):
            unit = "seconds" if option == Field("timeout") else "milliseconds"
            raise InputError(option, f"{value:g}", f"must be a positive number of {unit}",
                             "give a positive number")
    if max_decisions < 1:
        raise InputError(Field("max_decisions"), str(max_decisions), "must be at least 1",
                         "give a positive count")


def _load(spec: str) -> tuple[Callable, type | None, Finding]:
    """Step 1: the spec's factory, its class (None where the factory is no class) and the finding
    that it loaded; InputError when it cannot be loaded."""
    if spec in BUILTIN or spec.startswith((REMOTE_PREFIX, LLM_PREFIX)):
        factory = agent_factory(spec)
        return factory, factory if isinstance(factory, type) else None, Finding(True, f"{spec}: loaded")
    cls = load_class(spec)
    return cls, cls, Finding(True, f"class {spec.rpartition(':')[2]} loaded from {spec.rpartition(':')[0]}")


def _missing_methods(cls: type | None) -> list[Finding]:
    """Step 2: a problem for each protocol method the class lacks."""
    if cls is None:
        return []
    found = []
    for m in ("reset", "act"):
        if not callable(getattr(cls, m, None)):
            sig = "reset(self, info: EpisodeInfo) -> None" if m == "reset" else \
                "act(self, obs: Observation) -> Action"
            found.append(Finding(False, f"missing method {m}(): add `def {sig}`"))
    return found


def _attributes(probe: object) -> list[Finding]:
    """Step 3: the instance's ``name`` and ``privileged`` attributes."""
    found = []
    name, privileged = getattr(probe, "name", None), getattr(probe, "privileged", None)
    if not isinstance(name, str) or not name:
        found.append(Finding(False, "no `name` attribute (a non-empty string): results would be stored under "
                                    f"the spec; add e.g. name = \"{type(probe).__name__.lower()}\""))
    else:
        found.append(Finding(True, f"name = {name!r}"))
    if not isinstance(privileged, bool):
        found.append(Finding(False, "no `privileged` attribute (True or False): add privileged = False (the "
                                    "agent then sees only the BEV raster, speed, instruction and notice)"))
    elif privileged:
        found.append(Finding(None, "privileged = True: it receives the simulator's World view, as the "
                                   "built-in baselines do; an agent under test sets privileged = False"))
    else:
        found.append(Finding(True, "privileged = False"))
    return found


def _determinism(first: _Run, second: _Run) -> Finding | None:
    """Step 4: whether a second fresh instance with the same seed acted the same (None: nothing
    to say, the first run had a problem and the runs agree)."""
    diff = next((i for i, (a, b) in enumerate(zip(first.actions, second.actions)) if not _same(a, b)), None)
    if diff is None and len(first.actions) != len(second.actions) and not (first.problem and second.problem):
        diff = min(len(first.actions), len(second.actions))
    if diff is not None:
        a = _show(first.actions[diff]) if diff < len(first.actions) else first.problem or "(run ended)"
        b = _show(second.actions[diff]) if diff < len(second.actions) else second.problem or "(run ended)"
        return Finding(False, f"not deterministic: two runs with the same seed differ at decision "
                              f"{diff + 1}: {a} vs {b} (draw randomness from "
                              f"numpy.random.default_rng(info.seed) in reset, never a global RNG)")
    if not first.problem:
        return Finding(True, f"deterministic: a second run with the same seed gave the same "
                             f"{len(second.actions)} actions")
    return None


def _speed(times: list[float], max_act_ms: float) -> Finding | None:
    """Step 5: the mean time of ``act`` against the budget (None: no act call finished)."""
    if not times:
        return None
    mean_ms, worst_ms = 1000 * float(np.mean(times)), 1000 * float(np.max(times))
    if mean_ms > max_act_ms:
        hours = mean_ms / 1000 * DEFAULT_RUN_EPISODES * 300 / 3600  # ~300 decisions per tiny episode
        return Finding(False, f"too slow: act() takes {mean_ms:.0f} ms on average (max "
                              f"{worst_ms:.0f} ms), over the {max_act_ms:g} ms budget; "
                              f"the default evaluation would spend about "
                              f"{hours:.1f} h in act()")
    return Finding(True, f"speed: act() {mean_ms:.2f} ms on average (max {worst_ms:.2f} ms)")


def _batch_hook(probe: object, factory: Callable, caller: ThreadWatch, first: _Run,
                timeout: float) -> Finding | None:
    """Step 6: the optional ``act_batch`` hook, two fresh sessions fed the first run's observations
    in step, against what ``act`` returned (None: no hook, or no observation to feed)."""
    hook = batch_hook(type(probe))
    if not first.observations or hook is None:
        return None
    try:
        pair = [_timed(caller, factory)[0] for _ in range(2)]
        for a in pair:
            _timed(caller, a.reset, first.info)
        for i, o in enumerate(first.observations):
            batch, _ = _timed(caller, hook, pair, [o, o])
            if not isinstance(batch, (list, tuple)) or len(batch) != 2:
                return Finding(False, "act_batch() must return one action per observation "
                                      "(a list of 2 for 2)")
            if not all(_same(validate_action(a), first.actions[i]) for a in batch):
                return Finding(False, f"act_batch() returns other actions than act() at decision "
                                      f"{i + 1}: served remotely it would drive differently")
        return Finding(True, f"act_batch() matches act() over {len(first.observations)} "
                             f"decisions of 2 sessions")
    except AgentTimeout:
        return Finding(False, f"act_batch() did not answer within {timeout:g} s")
    except (Exception, SystemExit) as err:
        return Finding(False, _raised("act_batch()", err))


def check_agent(spec: str, route: str = DEFAULT_ROUTE, suite: str = DEFAULT_SUITE, timeout: float = 10.0,
                max_act_ms: float = MAX_ACT_MS, max_decisions: int = MAX_DECISIONS) -> CheckReport:
    """Check agent ``spec``; InputError when the spec cannot be loaded at all (bad input)."""
    _check_limits(timeout, max_act_ms, max_decisions)
    factory, cls, loaded = _load(spec)
    missing = _missing_methods(cls)
    found = [loaded, *missing]

    def report(*more: Finding | None) -> CheckReport:
        return CheckReport(spec, route, tuple(found) + tuple(f for f in more if f is not None))

    if missing:
        return report()
    # 3. scenario, a probe instance and the first run
    sc_dir, instr = bundled_route(route, suite)
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.world.scenario import read_scenario

    scenario = read_scenario(sc_dir)
    iset = read_instruction_sets(instr)[0]
    caller = ThreadWatch(timeout)
    try:
        probe, _ = _timed(caller, factory)
    except AgentTimeout:
        return report(Finding(False, f"creating the agent did not finish within {timeout:g} s"))
    except (Exception, SystemExit) as err:
        return report(Finding(False, _raised(f"creating the agent ({spec.rpartition(':')[2]}())", err)))
    found += _attributes(probe)
    if callable(getattr(probe, "close", None)):
        with contextlib.suppress(Exception):  # a later run reports close() problems
            _timed(caller, probe.close)
    first = _drive(factory, caller, scenario, iset, timeout, max_decisions, keep_obs=4)
    runs = f"{len(first.actions)} decisions on {scenario.route_id} ({first.termination or 'not finished'})"
    found.append(Finding(False, first.problem) if first.problem else Finding(True, f"actions valid: {runs}"))
    if first.hung:
        return report()
    second = _drive(factory, caller, scenario, iset, timeout, max_decisions, keep_obs=0)
    if second.hung:
        return report(Finding(False, second.problem))
    # 4. to 7.: determinism, speed, the act_batch hook, CPU independence
    return report(_determinism(first, second), _speed(first.act_s + second.act_s, max_act_ms),
                  _batch_hook(probe, factory, caller, first, timeout),
                  _cpu_independence(probe, first.observations))


def _cpu_independence(agent: object, observations: list) -> Finding:
    """Whether ``agent``'s actions are the same on every CPU: for an exact checkpoint, its fast
    path against the int64 reference on the observations of the first run."""
    policy = getattr(agent, "policy", None)
    from icrsumo.learn.exact.model import ExactPolicy

    if isinstance(policy, ExactPolicy) and observations:
        from icrsumo.learn.exact.proof import Frames, prove
        from icrsumo.learn.labels import StopClock

        clock = StopClock()
        stopped = np.array([clock.update(o.t, o.speed) for o in observations], np.float32)
        frames = Frames(np.packbits(np.stack([o.bev > 0 for o in observations]), axis=-1),
                        tuple(o.instruction for o in observations),
                        np.array([o.speed for o in observations], np.float32), stopped)
        r = prove(policy.checkpoint, frames)
        if r.exact:
            return Finding(True, f"CPU-independent: exact checkpoint, its fast path equals the int64 "
                                 f"reference bit for bit on {r.frames} observations (1 and 2 threads, "
                                 "batches of 1 and 32)")
        return Finding(False, f"not CPU-independent: the exact checkpoint's fast path differs from the "
                              f"int64 reference on {r.mismatches} of {r.frames} observations ({r.first})")
    if getattr(agent, "path", "").endswith(".pt"):
        return Finding(None, "not CPU-independent: a float checkpoint's actions depend on the CPU; make it "
                             "exact with icrsumo export-exact (docs/exact.md)")
    return Finding(None, "CPU independence not checked: only exact checkpoints prove it (docs/exact.md)")
