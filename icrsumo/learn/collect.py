"""``icrsumo collect``: expert driving data for the learned agents, from training routes only
(the ``train`` split on icrsumo's towns, ``carla-train`` and ``carla-focus`` on CARLA's; never an
evaluation suite).

The expert is the route-oracle (it knows the route). On every agent step (10 Hz) it plans from
the current state; its plan, resampled at :data:`icrsumo.learn.labels.ARC_M`, and its target
speed are the labels. On perturbed passes the executed action is disturbed now and then (the
start too): the waypoints are shifted sideways or rotated for 0.3-1.5 s, or the speed is scaled
for 1-3 s, so the ego leaves the lane centre, and the expert's labels from those states say how
to get back (recovery data, as in DAgger-style noise injection).

Instructions: each pass draws its own phrasings of the route's baseline sequence from the
baseline bank (seed from ``--seed``, the route id and the pass); the evaluation banks
(paraphrase, ambiguity, noise, misleading) are never read.

Layout of OUT (resumable: finished episodes are kept and skipped on a rerun):

    OUT/scenarios/                 convert-routes output of the split
    OUT/episodes/<route>__p<k>.npz one file per (route, pass), written atomically
    OUT/collect.json               options and the episode list (written last)

Each ``.npz`` holds ``bev`` (N, C, H, W/8) uint8 bit-packed raster (``numpy.unpackbits`` along
the last axis restores 0/1), ``speed`` (N,) m/s, ``instruction`` (N,) int16 index into
``instructions`` (a JSON list of the episode's instructions: text as shown, type, intent, slots;
-1 before the first; with ``memory`` on, the last entry is "Follow the road.", recorded for the
frames where the learned agents' instruction memory would hand the network that text instead of
the active instruction), ``waypoints`` (N, K, 2) m ego frame, ``target_speed`` (N,) m/s,
``perturbed`` (N,) uint8, ``t`` (N,) s and ``stopped_for`` (N,) s (time since the ego
stopped, 0 while moving; see :class:`icrsumo.learn.labels.StopClock`). :func:`read_episode`
reads one back, checked (``icrsumo train`` reads them with it).

Bad options (an evaluation split, counts out of range, a ``--driver`` whose checkpoint is
missing, damaged or does not fit its model) are InputErrors raised before anything is written.
"""

from __future__ import annotations

import io
import json
import sys
import zipfile
import zlib
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from icrsumo.agents.base import Action, Observation
from icrsumo.agents.privileged import RouteOracle
from icrsumo.core.errors import Field, InputError, check_seed, expect
from icrsumo.core.fsio import OutFolder, dumps_json, read_json_doc, write_atomic
from icrsumo.core.resources import bundled_suites, suite_coords
from icrsumo.core.types import Instruction
from icrsumo.core.vocab import Intent, Termination
from icrsumo.instructions.banks import load_banks
from icrsumo.instructions.baseline import LEAD_STREAM
from icrsumo.instructions.generate import baseline_set
from icrsumo.world.convert import ConvertOptions, convert_routes, safe_name
from icrsumo.world.scenario import find_scenarios, read_scenario

from .augment import instruction_slots
from .labels import ARC_M, StopClock, resample_path
from .memory import FOLLOW_TEXT, InstructionMemory

COLLECT_FORMAT = "icrsumo-collect/1"
#: bundled suites that hold evaluation routes (icrsumo's splits, LangAuto's tracks): never
#: collected from, by name or by their file's path
EVAL_SPLITS = ("tiny", "short", "long", "langauto-tiny", "langauto-short", "langauto-long")
#: terminations after which the frames of the final standstill longer than STUCK_AFTER_S (s)
#: are dropped
STUCK = (Termination.AGENT_BLOCKED, Termination.ROUTE_TIMEOUT)
STUCK_AFTER_S = 20.0
#: chance per agent step (10 Hz) that a perturbation starts on a perturbed pass
P_START = 0.04


@dataclass(frozen=True)
class CollectOptions:
    """What to collect: ``passes`` per route (pass 0 clean, the others perturbed), every
    ``every``-th agent step stored, background ``traffic`` level, ``limit`` routes (0: all).
    ``driver``: a learned agent (name or checkpoint) that drives instead of the expert while the
    expert still labels every frame (DAgger); no perturbations then. ``memory``: each frame
    records the text a learned agent's instruction memory would hand its network at that step
    (:class:`icrsumo.learn.memory.InstructionMemory` on the driven ego's compass and speed:
    "Follow the road." once a turn or lane change is used up, or while a named distance is
    still ahead), so that the network is trained on the text it reads when it drives; off: the
    active instruction (data collected before issue 47's memory). ``vary_leads``: each junction
    maneuver's instructions arrive at distances drawn per maneuver
    (:data:`icrsumo.instructions.baseline.VARIED_LEADS`) instead of the benchmark's fixed
    layout, the same phrasings and perturbations otherwise."""

    suite: str = "train"
    passes: int = 3
    seed: int = 0
    every: int = 2
    traffic: str = "normal"
    workers: int = 1
    limit: int = 0
    driver: str = ""
    memory: bool = True
    vary_leads: bool = False

    def check(self) -> None:
        if self.suite in EVAL_SPLITS or _is_eval_file(self.suite):
            raise InputError(Field("suite"), self.suite, "is an evaluation split",
                             "collect from the train split (the default), carla-train or "
                             "carla-focus (CARLA's towns) or your own routes")
        if not 1 <= self.passes <= 32:
            raise InputError(Field("passes"), "", f"{self.passes} out of range", "use 1 to 32")
        if not 1 <= self.every <= 50:
            raise InputError(Field("every"), "", f"{self.every} out of range", "use 1 to 50")
        if self.workers < 1:
            raise InputError(Field("workers"), "", "must be at least 1", "give a positive count")
        check_seed(self.seed)
        if self.limit < 0:
            raise InputError(Field("limit"), "", f"{self.limit} is negative",
                             "give a route count >= 0 (0: all)")
        if self.driver:
            self._check_driver()

    def _check_driver(self) -> None:
        """A ``driver`` that is a registered non-privileged agent, or a checkpoint whose file
        loads and fits its model (checked here, before anything is written or driven)."""
        from icrsumo.agents.registry import BUILTIN

        from .agent import checkpoint_path, read_checkpoint

        cls = BUILTIN.get(self.driver)
        if cls is not None:
            if getattr(cls, "privileged", False):
                raise InputError(Field("driver"), self.driver, "is a privileged agent (it needs the "
                                 "simulator's state, which a driver does not see)",
                                 "give a learned agent or a checkpoint")
            return
        read_checkpoint(checkpoint_path(self.driver))


def _is_eval_file(suite: str) -> bool:
    """Whether ``suite`` is the path of a bundled evaluation suite's route file."""
    p = Path(suite)
    if not p.is_file():
        return False
    suites = bundled_suites()
    return any(p.resolve() == suites[s].resolve() for s in EVAL_SPLITS if s in suites)


class Collector(RouteOracle):
    """The route-oracle that records (BEV, speed, instruction, its own plan) and, when
    ``perturb`` is set, executes a disturbed version of its plan now and then."""

    name = "collector"

    def __init__(self, rng: np.random.Generator, perturb: bool, every: int, driver: object = None,
                 memory: bool = False, follow_index: int = -1) -> None:
        super().__init__()
        self.rng, self.perturb, self.every, self.driver = rng, perturb, every, driver
        # with memory: frames whose text the memory replaces record ``follow_index``
        self.memory, self.follow_index = memory, follow_index
        self.recall, self.dt = InstructionMemory(), 0.1
        self.rows: dict[str, list] = {k: [] for k in ("bev", "speed", "instruction", "waypoints",
                                                       "target_speed", "perturbed", "t", "stopped_for")}
        self._n = 0
        self._clock = StopClock()
        self._left = 0
        self._kind = ""
        self._value = 0.0

    def act(self, obs: Observation) -> Action:
        label = super().act(obs)
        stopped_for = self._clock.update(obs.t, obs.speed)
        instruction = obs.instruction_id
        if self.memory and self.recall.text(obs, self.dt) != obs.instruction:
            instruction = self.follow_index
        if self.perturb:
            self._schedule()
        if self._n % self.every == 0:
            r = self.rows
            r["bev"].append(np.packbits(obs.bev > 0, axis=-1))
            r["speed"].append(obs.speed)
            r["instruction"].append(instruction)
            r["waypoints"].append(resample_path(label.waypoints))
            r["target_speed"].append(label.target_speed or 0.0)
            r["perturbed"].append(1 if self._left > 0 else 0)
            r["t"].append(obs.t)
            r["stopped_for"].append(stopped_for)
        self._n += 1
        if self.driver is not None:
            return self.driver.act(replace(obs, world=None))
        return self._disturb(label)

    def reset(self, info) -> None:
        super().reset(info)
        self.recall, self.dt = InstructionMemory(), float(info.control_dt)
        if self.driver is not None:
            self.driver.reset(info)

    def _schedule(self) -> None:
        rng = self.rng
        if self._left > 0:
            return
        if not (self._n == 0 and rng.random() < 0.7) and not rng.random() < P_START:
            return
        kind = ("shift", "turn", "speed")[int(rng.integers(3))] if self._n else "shift"
        sign = 1.0 if rng.random() < 0.5 else -1.0
        if kind == "shift":
            self._value, self._left = sign * rng.uniform(0.8, 2.5), int(rng.integers(5, 16))
        elif kind == "turn":
            self._value, self._left = sign * rng.uniform(0.08, 0.3), int(rng.integers(3, 9))
        else:
            self._value, self._left = rng.uniform(0.3, 1.4), int(rng.integers(10, 31))
        self._kind = kind

    def _disturb(self, a: Action) -> Action:
        if self._left <= 0:
            return a
        self._left -= 1
        wps = np.asarray(a.waypoints, dtype=float)
        if self._kind == "shift":
            return Action(waypoints=wps + np.array([0.0, self._value]), target_speed=a.target_speed)
        if self._kind == "turn":
            c, s = np.cos(self._value), np.sin(self._value)
            return Action(waypoints=wps @ np.array([[c, s], [-s, c]]), target_speed=a.target_speed)
        return Action(waypoints=wps, target_speed=(a.target_speed or 0.0) * self._value)


#: per-frame arrays of an episode file: trailing shape and dtype kind (u: unsigned, i: signed
#: integer, f: float); the BEV shape is the models' input (7 channels, 128 x 128 bit-packed)
EPISODE_ARRAYS = {"bev": ((7, 128, 16), "u"), "speed": ((), "f"), "instruction": ((), "i"),
                  "waypoints": ((len(ARC_M), 2), "f"), "target_speed": ((), "f"), "perturbed": ((), "u"),
                  "t": ((), "f"), "stopped_for": ((), "f")}
_DAMAGED = (OSError, ValueError, EOFError, KeyError, TypeError, zipfile.BadZipFile, zlib.error)


def read_episode(path: Path, keys: tuple[str, ...] = tuple(EPISODE_ARRAYS)) -> tuple[dict, list[dict]]:
    """The arrays ``keys`` of one episode file (:data:`EPISODE_ARRAYS`) and, with
    ``instruction`` among them, its instruction documents (``instructions``), checked: a
    missing, truncated or damaged file, a missing or misshapen array, non-finite labels and
    instruction indices out of range are InputErrors naming the file."""
    path = Path(path)
    fix = f"delete it and rerun icrsumo collect --out {path.parent.parent} with the same options"
    if not path.is_file():
        raise InputError(path, "", "episode file not found (listed in collect.json)",
                         f"rerun icrsumo collect --out {path.parent.parent} with the same options: it "
                         "drives missing episodes again")
    out: dict[str, np.ndarray] = {}
    want_docs = "instruction" in keys
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
        if not head:
            raise InputError(path, "", "episode file is empty (0 bytes)", fix)
        if not head.startswith(b"PK"):  # np.load would try to unpickle it
            raise InputError(path, "", "is not an episode file (not an .npz archive)", fix)
        z = np.load(path)
        if not isinstance(z, np.lib.npyio.NpzFile):
            raise InputError(path, "", "is not an episode file (not an .npz archive)", fix)
        with z:
            missing = [k for k in (*keys, *(("instructions",) if want_docs else ())) if k not in z.files]
            if missing:
                raise InputError(path, "", f"episode file lacks {', '.join(missing)}", fix)
            for k in keys:
                out[k] = z[k]
            text = str(z["instructions"]) if want_docs else "[]"
    except InputError:
        raise
    except _DAMAGED as err:
        detail = (str(err).splitlines() or [""])[0][:120]
        raise InputError(path, "", f"episode file is truncated or damaged ({type(err).__name__}"
                         f"{': ' + detail if detail else ''})", fix) from None
    n = len(out[keys[0]]) if keys and out[keys[0]].ndim else -1
    for k in keys:
        tail, kind = EPISODE_ARRAYS[k]
        a = out[k]
        if a.ndim != 1 + len(tail) or a.shape[0] != n or a.shape[1:] != tail or a.dtype.kind not in kind:
            want = str((n, *tail)) if n >= 0 else f"(N{''.join(f', {d}' for d in tail)})"
            raise InputError(path, k, f"array of shape {a.shape} and dtype {a.dtype}, not {want} "
                             f"{dict(u='unsigned integers', i='integers', f='floats')[kind]}", fix)
        if kind == "f" and not np.isfinite(a).all():
            raise InputError(path, k, "holds non-finite values (NaN or infinity)", fix)
    try:
        docs = json.loads(text)
    except json.JSONDecodeError as err:
        raise InputError(path, "instructions", f"malformed JSON ({err.msg})", fix) from None
    expect(docs, list, path, "instructions", "the instruction list", fix)
    for i, d in enumerate(docs):
        expect(d, dict, path, f"instructions[{i}]", "an instruction", fix)
        for key, kinds in (("text", str), ("type", str), ("intent", str), ("slots", dict)):
            expect(d.get(key), kinds, path, f"instructions[{i}].{key}", key, fix)
        if d.get("distance") is not None:
            expect(d["distance"], (int, float), path, f"instructions[{i}].distance", "distance", fix)
        for k, v in d["slots"].items():
            expect(v, str, path, f"instructions[{i}].slots.{k}", "a slot value", fix)
    if "instruction" in out and len(out["instruction"]) and (
            out["instruction"].min() < -1 or out["instruction"].max() >= len(docs)):
        raise InputError(path, "instruction", f"indices outside -1..{len(docs) - 1}", fix)
    return out, docs


def _instruction_doc(ins: Instruction) -> dict:
    return {"id": ins.id, "text": ins.rendered(), "type": ins.type, "intent": ins.intent.value,
            "distance": ins.distance, "slots": instruction_slots(ins)}


#: the instruction document of the text the memory hands the network in place of the active one
FOLLOW_DOC = {"id": -1, "text": FOLLOW_TEXT, "type": "follow", "intent": Intent.FOLLOW.value,
              "distance": None, "slots": {}}


def episode_rng(seed: int, route_id: str, pass_k: int) -> np.random.Generator:
    """The Generator of one (route, pass): phrasings and perturbations."""
    return np.random.default_rng([seed, zlib.crc32(route_id.encode("utf-8")), pass_k])


def collect_episode(scenario_dir: str, pass_k: int, opts: CollectOptions) -> tuple[bytes, dict]:
    """Drive one (route, pass); returns the ``.npz`` bytes and a summary dict."""
    from icrsumo.sim.episode import run_episode

    sc = read_scenario(Path(scenario_dir))
    rng = episode_rng(opts.seed, sc.route_id, pass_k)
    phrasing_seed = int(rng.integers(2**31))
    lead_rng = np.random.default_rng([phrasing_seed, LEAD_STREAM]) if opts.vary_leads else None
    iset, _ = baseline_set(sc, load_banks(None), phrasing_seed, lead_rng=lead_rng)
    driver = None
    if opts.driver:
        from icrsumo.agents.registry import BUILTIN

        from .agent import LearnedAgent

        cls = BUILTIN.get(opts.driver)
        driver = cls() if cls is not None else LearnedAgent(opts.driver)
    docs = [_instruction_doc(i) for i in iset.instructions]
    agent = Collector(rng, perturb=pass_k > 0 and driver is None, every=opts.every, driver=driver,
                      memory=opts.memory, follow_index=len(docs))
    log = run_episode(sc, iset, agent)
    r = agent.rows
    if log.termination in STUCK:
        # the expert got stuck: its final standstill is no demonstration
        keep = len(r["speed"])
        while keep and r["stopped_for"][keep - 1] >= STUCK_AFTER_S:
            keep -= 1
        r = {k: v[:keep] for k, v in r.items()}
    arrays = {
        "bev": np.stack(r["bev"]).astype(np.uint8),
        "speed": np.asarray(r["speed"], dtype=np.float32),
        "instruction": np.asarray(r["instruction"], dtype=np.int16),
        "waypoints": np.stack(r["waypoints"]).astype(np.float32),
        "target_speed": np.asarray(r["target_speed"], dtype=np.float32),
        "perturbed": np.asarray(r["perturbed"], dtype=np.uint8),
        "t": np.asarray(r["t"], dtype=np.float32),
        "stopped_for": np.asarray(r["stopped_for"], dtype=np.float32),
        "instructions": np.asarray(json.dumps(docs + [FOLLOW_DOC] if opts.memory else docs)),
    }
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    summary = {"route_id": sc.route_id, "pass": pass_k, "frames": len(r["speed"]),
               "termination": log.termination,
               "progress": round(log.progress[-1] if log.progress else 0.0, 1)}
    return buf.getvalue(), summary


def _job(args: tuple[str, int, CollectOptions, str]) -> dict:
    d, k, opts, path = args
    data, summary = collect_episode(d, k, opts)
    write_atomic(Path(path), data)
    return summary


def _scenarios(opts: CollectOptions, out: Path) -> Path:
    p = Path(opts.suite)
    if p.is_dir() and (p / "index.json").is_file():
        return p
    routes = bundled_suites().get(opts.suite, p)
    if not Path(routes).is_file():
        raise InputError(opts.suite, "", "no such route file or bundled split",
                         "use train (the default), carla-train, carla-focus or a route XML file")
    coords = suite_coords(opts.suite) or "sumo"  # a bundled suite knows its frame (carla-*: carla)
    report = convert_routes(routes, out / "scenarios", ConvertOptions(
        coords=coords, traffic=opts.traffic, workers=opts.workers))
    for line in report.failures:
        print(f"icrsumo: skipped: {line}", file=sys.stderr)
    return out / "scenarios"


def collect(opts: CollectOptions, out: Path, quiet: bool = False) -> dict:
    """Collect (or resume collecting) into ``out``; returns the manifest written to
    ``out/collect.json``."""
    opts.check()
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(out, "", "exists and is not a folder",
                         f"give a new or an earlier {Field('out')} folder")
    config = {k: v for k, v in asdict(opts).items() if k not in ("workers",)}
    manifest_path = out / "collect.json"
    if manifest_path.exists():
        old = read_json_doc(manifest_path, COLLECT_FORMAT, "collect manifest",
                           f"use another {Field('out')} folder, or delete the damaged collect.json and "
                           "rerun with the same options (finished episodes are kept)").get("config", {})
        old.setdefault("memory", False)   # folders collected before the option existed
        old.setdefault("vary_leads", False)
        if old != config:
            raise InputError(manifest_path, "config", "holds data of a different configuration",
                             f"use another {Field('out')} folder, or the same options")
    before = OutFolder.before(out)
    try:
        dirs = find_scenarios(_scenarios(opts, out))
        if not dirs:
            raise InputError(opts.suite, "", "no scenario to collect from (no route converted)",
                             f"fix the routes named above, or give another {Field('suite')}")
    except InputError:
        before.undo()  # refused before any driving: leave no half-made folder behind
        raise
    if opts.limit:
        dirs = dirs[: opts.limit]
    episodes = out / "episodes"
    episodes.mkdir(parents=True, exist_ok=True)
    jobs, names = [], []
    for d in dirs:
        rid = read_scenario(d).route_id
        for k in range(opts.passes):
            path = episodes / f"{safe_name(rid)}__p{k}.npz"
            names.append(path.name)
            if not path.is_file():
                jobs.append((str(d), k, opts, str(path)))
    if jobs and not quiet:
        print(f"icrsumo collect: {len(jobs)} episodes to drive ({len(names) - len(jobs)} kept)",
              file=sys.stderr)
    if opts.workers > 1 and len(jobs) > 1:
        with ProcessPoolExecutor(max_workers=min(opts.workers, len(jobs))) as pool:
            for i, _ in enumerate(pool.map(_job, jobs), 1):
                if not quiet and i % 20 == 0:
                    print(f"icrsumo collect: {i}/{len(jobs)}", file=sys.stderr)
    else:
        for job in jobs:
            _job(job)
    frames = sum(len(read_episode(episodes / name, ("speed",))[0]["speed"]) for name in names)
    manifest = {"format": COLLECT_FORMAT, "config": config, "frames": frames, "episodes": names}
    write_atomic(manifest_path, dumps_json(manifest))
    return manifest
