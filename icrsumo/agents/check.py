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
import queue
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..cache import DEFAULT_ROUTE, DEFAULT_SUITE, bundled_route
from ..errors import InputError
from .base import Action, AgentError, Observation, batch_hook, validate_action
from .registry import BUILTIN, REMOTE_PREFIX, agent_factory, load_class

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


class _Hung(Exception):
    pass


class _Caller:
    """Runs calls on one daemon thread with a time limit (a hung call keeps that thread)."""

    def __init__(self) -> None:
        self._in: queue.Queue = queue.Queue()
        threading.Thread(target=self._loop, name="icrsumo-check-agent", daemon=True).start()

    def _loop(self) -> None:
        while True:
            fn, args, box, done = self._in.get()
            t0 = time.perf_counter()
            try:
                box["value"] = fn(*args)
            except BaseException as err:  # reported to the caller
                box["error"] = err
            box["dt"] = time.perf_counter() - t0
            done.set()

    def call(self, timeout: float, fn: Callable, *args: Any) -> tuple[Any, float]:
        """(result, seconds); re-raises the call's exception; _Hung after ``timeout`` s."""
        box: dict[str, Any] = {}
        done = threading.Event()
        self._in.put((fn, args, box, done))
        if not done.wait(timeout):
            raise _Hung
        if "error" in box:
            raise box["error"]
        return box.get("value"), box["dt"]


def _where(err: BaseException) -> str:
    tb = traceback.extract_tb(err.__traceback__)
    return f" (at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno})" if tb else ""


def _raised(what: str, err: BaseException) -> str:
    return f"{what} raised {type(err).__name__}: {err}{_where(err)}"


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


def _drive(factory: Callable, caller: _Caller, scenario, iset, timeout: float, max_decisions: int,
           keep_obs: int) -> _Run:
    from ..runner import Episode, RunOptions

    run = _Run([], [], [])
    try:
        agent, _ = caller.call(timeout, factory)
    except _Hung:
        run.problem, run.hung = f"creating the agent did not finish within {timeout:g} s", True
        return run
    except Exception as err:
        run.problem = _raised("creating the agent", err)
        return run
    privileged = bool(getattr(agent, "privileged", False))
    with Episode(scenario, iset, RunOptions(), privileged=privileged) as ep:
        run.info = ep.info
        try:
            caller.call(timeout, agent.reset, ep.info)
        except _Hung:
            run.problem, run.hung = f"reset() did not answer within {timeout:g} s", True
            return run
        except Exception as err:
            run.problem = _raised("reset(info)", err)
            return run
        obs = ep.start()
        while obs is not None and len(run.actions) < max_decisions:
            n = len(run.actions) + 1
            at = f"act() at decision {n} (t = {obs.t:.2f} s)"
            try:
                action, dt = caller.call(timeout, agent.act, obs)
            except _Hung:
                run.problem, run.hung = f"{at} did not answer within {timeout:g} s", True
                break
            except Exception as err:
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
            caller.call(timeout, agent.close)
        except (_Hung, Exception) as err:  # noqa: BLE001 - reported, never fatal
            if not run.problem:
                run.problem = "close() did not answer" if isinstance(err, _Hung) else _raised("close()", err)
    return run


def check_agent(spec: str, route: str = DEFAULT_ROUTE, suite: str = DEFAULT_SUITE, timeout: float = 10.0,
                max_act_ms: float = MAX_ACT_MS, max_decisions: int = MAX_DECISIONS) -> CheckReport:
    """Check agent ``spec``; InputError when the spec cannot be loaded at all (bad input)."""
    if not timeout > 0 or not max_act_ms > 0 or max_decisions < 1:
        raise InputError("check-agent", "", "--timeout and --max-act-ms must be positive, --decisions >= 1",
                         "give positive numbers")
    found: list[Finding] = []

    def report() -> CheckReport:
        return CheckReport(spec, route, tuple(found))

    # 1. load
    if spec in BUILTIN or spec.startswith(REMOTE_PREFIX):
        factory = agent_factory(spec)
        found.append(Finding(True, f"{spec}: loaded"))
        cls = factory if isinstance(factory, type) else None
    else:
        cls = factory = load_class(spec)
        found.append(Finding(True, f"class {spec.rpartition(':')[2]} loaded from {spec.rpartition(':')[0]}"))
    # 2. protocol members of the class
    if cls is not None:
        missing = [m for m in ("reset", "act") if not callable(getattr(cls, m, None))]
        for m in missing:
            sig = "reset(self, info: EpisodeInfo) -> None" if m == "reset" else \
                "act(self, obs: Observation) -> Action"
            found.append(Finding(False, f"missing method {m}(): add `def {sig}`"))
        if missing:
            return report()
    # 3. scenario and the first run
    sc_dir, instr = bundled_route(route, suite)
    from ..instructions.store import read_instruction_sets
    from ..scenario import read_scenario

    scenario = read_scenario(sc_dir)
    iset = read_instruction_sets(instr)[0]
    caller = _Caller()
    try:
        probe, _ = caller.call(timeout, factory)
    except _Hung:
        found.append(Finding(False, f"creating the agent did not finish within {timeout:g} s"))
        return report()
    except Exception as err:
        found.append(Finding(False, _raised(f"creating the agent ({spec.rpartition(':')[2]}())", err)))
        return report()
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
    if callable(getattr(probe, "close", None)):
        with contextlib.suppress(_Hung, Exception):  # a later run reports close() problems
            caller.call(timeout, probe.close)
    first = _drive(factory, caller, scenario, iset, timeout, max_decisions, keep_obs=4)
    runs = f"{len(first.actions)} decisions on {scenario.route_id} ({first.termination or 'not finished'})"
    if first.problem:
        found.append(Finding(False, first.problem))
        if first.hung:
            return report()
    else:
        found.append(Finding(True, f"actions valid: {runs}"))
    # 4. determinism: a second fresh instance, same seed
    second = _drive(factory, caller, scenario, iset, timeout, max_decisions, keep_obs=0)
    if second.hung:
        found.append(Finding(False, second.problem))
        return report()
    diff = next((i for i, (a, b) in enumerate(zip(first.actions, second.actions)) if not _same(a, b)), None)
    if diff is None and len(first.actions) != len(second.actions) and not (first.problem and second.problem):
        diff = min(len(first.actions), len(second.actions))
    if diff is not None:
        a = _show(first.actions[diff]) if diff < len(first.actions) else first.problem or "(run ended)"
        b = _show(second.actions[diff]) if diff < len(second.actions) else second.problem or "(run ended)"
        found.append(Finding(False, f"not deterministic: two runs with the same seed differ at decision "
                                    f"{diff + 1}: {a} vs {b} (draw randomness from "
                                    f"numpy.random.default_rng(info.seed) in reset, never a global RNG)"))
    elif not first.problem:
        found.append(Finding(True, f"deterministic: a second run with the same seed gave the same "
                                   f"{len(second.actions)} actions"))
    # 5. speed
    times = first.act_s + second.act_s
    if times:
        mean_ms, worst_ms = 1000 * float(np.mean(times)), 1000 * float(np.max(times))
        if mean_ms > max_act_ms:
            hours = mean_ms / 1000 * DEFAULT_RUN_EPISODES * 300 / 3600  # ~300 decisions per tiny episode
            found.append(Finding(False, f"too slow: act() takes {mean_ms:.0f} ms on average (max "
                                        f"{worst_ms:.0f} ms), over the {max_act_ms:g} ms budget "
                                        f"(--max-act-ms); the default evaluation would spend about "
                                        f"{hours:.1f} h in act()"))
        else:
            found.append(Finding(True, f"speed: act() {mean_ms:.2f} ms on average (max {worst_ms:.2f} ms)"))
    # 6. the optional act_batch hook: two fresh sessions fed run 1's observations in step
    hook = batch_hook(type(probe))
    if first.observations and hook is not None:
        try:
            pair = [caller.call(timeout, factory)[0] for _ in range(2)]
            for a in pair:
                caller.call(timeout, a.reset, first.info)
            for i, o in enumerate(first.observations):
                batch, _ = caller.call(timeout, hook, pair, [o, o])
                if not isinstance(batch, (list, tuple)) or len(batch) != 2:
                    found.append(Finding(False, "act_batch() must return one action per observation "
                                                "(a list of 2 for 2)"))
                    break
                if not all(_same(validate_action(a), first.actions[i]) for a in batch):
                    found.append(Finding(False, f"act_batch() returns other actions than act() at decision "
                                                f"{i + 1}: served remotely it would drive differently"))
                    break
            else:
                found.append(Finding(True, f"act_batch() matches act() over {len(first.observations)} "
                                           f"decisions of 2 sessions"))
        except _Hung:
            found.append(Finding(False, f"act_batch() did not answer within {timeout:g} s"))
        except Exception as err:
            found.append(Finding(False, _raised("act_batch()", err)))
    return report()
