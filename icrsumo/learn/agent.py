"""Learned agents: drive from the BEV raster, the speed and the instruction text alone.

A :class:`LearnedAgent` runs a policy (one per checkpoint, device and process, loaded on first
use) on each observation and hands its waypoints and target speed to the built-in controller; a
stop decision sets the target speed to 0. An exact checkpoint (``.npz``) runs in
:class:`icrsumo.learn.exact.model.ExactPolicy` (numpy, the same bits on every CPU, no torch); a
float one (``.pt``, read with ``weights_only=True``) in :class:`icrsumo.learn.nets.policy.Policy`
(ONNX Runtime or torch: the ``train`` extra), where the stop decision is a stop probability
above 0.5. It remembers the time it has been stopped (:class:`icrsumo.learn.labels.StopClock`)
and, with ``memory`` on (the default), what it has done under the active instruction: the turn or
lane change already driven, the distance come since it arrived
(:class:`icrsumo.learn.memory.InstructionMemory`, which chooses the text the network reads);
with ``creep`` on (the default) it drives on where its network would stand still for good with
nothing to wait for in view (:class:`icrsumo.learn.creep.Creep`).
``act_batch`` runs several episodes' observations in one forward pass per checkpoint, device and
runtime (:func:`act_batch`, used by batched serving). The inference device is a constructor
argument (``device``: cpu by default, cuda, cuda:N, auto).

Shipped checkpoints live in ``icrsumo/learn/checkpoints/<name>.npz`` (exact, what the agents
run) beside the float ``<name>.pt`` they were made from, a model card ``<name>.md`` and the
config ``<name>.toml`` that trained it.

A checkpoint that is missing, damaged, refused by the safe loader or does not fit its model,
and a device that is unknown or not available, are :class:`icrsumo.core.errors.InputError` lines
naming the file (or the device) when the agent is built.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np

from icrsumo.agents.base import Action, EpisodeInfo, Observation
from icrsumo.core.errors import InputError

from .creep import Creep
from .labels import StopClock
from .memory import InstructionMemory

CHECKPOINTS = Path(__file__).resolve().parent / "checkpoints"
_FIX = ("give the path of a model.pt written by icrsumo train (or its exact .npz), or a shipped agent "
        f"({', '.join(sorted(p.stem for p in CHECKPOINTS.glob('*.npz')))})")


@cache
def _policy(path: str, device: str, runtime: str = "onnx"):
    """The process's policy of checkpoint ``path`` on ``device`` in ``runtime`` (loaded once).
    An exact checkpoint (``.npz``, :mod:`icrsumo.learn.exact`) runs in numpy on the CPU whatever
    ``device`` and ``runtime`` say (no torch)."""
    if is_exact(path):
        from .exact.model import ExactPolicy

        return ExactPolicy(Path(path))
    from .nets import Policy

    return Policy(Path(path), device=device, runtime=runtime)


def is_exact(path: str | Path) -> bool:
    """Whether ``path`` names an exact checkpoint (``.npz``): CPU-independent, loaded without torch."""
    return Path(path).suffix == ".npz"


def read_checkpoint(path: Path) -> None:
    """Read and check a checkpoint of either kind (exact ``.npz`` without torch, float ``.pt``
    with it): the InputErrors loading it would raise, before anything runs."""
    if is_exact(path):
        from .exact.checkpoint import load

        load(path)
    else:
        from .nets import read_checkpoint as read_float

        read_float(path)


def checkpoint_path(checkpoint: str | Path) -> Path:
    """The file of a checkpoint given as a path or as a shipped checkpoint's file name
    (``bev-token.pt``); an InputError when there is no such file. Its content is checked when
    the policy loads (:func:`icrsumo.learn.nets.checkpoint.read_checkpoint`)."""
    if not str(checkpoint):
        raise InputError("checkpoint", "", "no agent checkpoint given", _FIX)
    path = Path(checkpoint)
    if not path.is_absolute() and not path.is_file() and (CHECKPOINTS / path).is_file():
        path = CHECKPOINTS / path
    if path.is_dir():
        raise InputError(path, "", "is a folder, not an agent checkpoint", "give the model.pt file in it")
    if not path.is_file():
        raise InputError(path, "", "agent checkpoint not found", _FIX)
    return path


class LearnedAgent:
    """A non-privileged agent around a checkpoint (``checkpoint``: a path) whose network runs
    on ``device`` (cpu, cuda, cuda:N, auto); on the CPU in ``runtime`` ``onnx`` (ONNX Runtime,
    the default) or ``torch`` (:class:`icrsumo.learn.nets.policy.Policy`). ``memory``: the
    network reads the text :class:`icrsumo.learn.memory.InstructionMemory` chooses (True, the
    default) or the active instruction as it stands (False: the agents before issue 47).
    ``creep``: after standing :data:`icrsumo.learn.creep.AFTER_S` seconds with nothing to wait
    for in view, override the network's stop for a moment (True, the default) or never (False:
    the agents before the creep, issue 47)."""

    name = "learned"
    privileged = False
    checkpoint: str = ""

    def __init__(self, checkpoint: str | Path | None = None, device: str = "cpu",
                 runtime: str = "onnx", memory: bool = True, creep: bool = True) -> None:
        path = checkpoint_path(checkpoint or self.checkpoint)
        self.path, self.device, self.runtime = str(path), device, runtime
        self.memory, self.creep = bool(memory), bool(creep)
        self.policy = _policy(self.path, device, runtime)
        self.clock = StopClock()
        self.recall, self.dt = InstructionMemory(), 0.1
        self.watch = Creep()

    def reset(self, info: EpisodeInfo) -> None:
        self.clock = StopClock()
        self.recall, self.dt = InstructionMemory(), float(info.control_dt)
        self.watch = Creep()

    def read(self, obs: Observation) -> str:
        """The text the network reads at this step (call once per step): the instruction memory's
        choice, or the active instruction itself with ``memory`` off."""
        return self.recall.text(obs, self.dt) if self.memory else obs.instruction

    def decide(self, obs: Observation, act: Action) -> Action:
        """The action taken at this step from the network's (call once per step): the creep's
        choice (:class:`icrsumo.learn.creep.Creep`), or the network's with ``creep`` off."""
        return self.watch.action(obs, act) if self.creep else act

    def act(self, obs: Observation) -> Action:
        # one observation: act_batch without the grouping (the same policy call, bitwise)
        stopped = self.clock.update(obs.t, obs.speed)
        out = self.policy(obs.bev[None], [self.read(obs)], np.array([obs.speed], dtype=np.float32),
                          np.array([stopped], dtype=np.float32))
        return self.decide(obs, _action(out["waypoints"][0], out["speed"][0], bool(_stops(out)[0])))

    #: batched-inference hook (``act_batch(agents, observations)``) used by serve-agent
    act_batch = staticmethod(lambda agents, batch: act_batch(agents, batch))


def act_batch(agents: list[LearnedAgent], batch: list[Observation]) -> list[Action]:
    """Actions of several episodes' agents (``agents[i]`` sees ``batch[i]``) with one forward
    pass per checkpoint, device and runtime: the batched-inference hook of ``icrsumo serve-agent`` and of
    parallel evaluation. Each agent keeps its own stop clock, instruction memory and creep."""
    actions: list[Action | None] = [None] * len(batch)
    groups: dict[tuple[str, str, str], list[int]] = {}
    for i, a in enumerate(agents):
        groups.setdefault((a.path, a.device, getattr(a, "runtime", "onnx")), []).append(i)
    for (path, device, runtime), idx in groups.items():
        policy = _policy(path, device, runtime)
        obs = [batch[i] for i in idx]
        stopped = np.array([agents[i].clock.update(o.t, o.speed) for i, o in zip(idx, obs)], dtype=np.float32)
        out = policy(np.stack([o.bev for o in obs]),
                     [agents[i].read(o) for i, o in zip(idx, obs)],
                     np.array([o.speed for o in obs], dtype=np.float32), stopped)
        for i, o, wps, v, stop in zip(idx, obs, out["waypoints"], out["speed"], _stops(out)):
            actions[i] = agents[i].decide(o, _action(wps, v, bool(stop)))
    return actions  # type: ignore[return-value]


def _stops(out: dict[str, np.ndarray]) -> np.ndarray:
    """(B,) bool: the policy's stop decisions (an exact policy gives them; a float one's stop
    probability above 0.5)."""
    return out["stop"] if "stop" in out else out["stop_prob"] > 0.5


def _action(wps: np.ndarray, speed: float, stop: bool) -> Action:
    """The action of one output row: waypoints (K, 2) m; target speed 0 when ``stop``, else
    the predicted speed (m/s, at least 0)."""
    target = 0.0 if stop else float(max(speed, 0.0))
    return Action(waypoints=wps.astype(np.float64), target_speed=target)


class TokenAgent(LearnedAgent):
    """``bev-token``: word-token GRU language encoder, trained on baseline phrasings only."""

    name = "bev-token"
    checkpoint = str(CHECKPOINTS / "bev-token.npz")  # the shipped exact file, never one in the cwd


class NgramAgent(LearnedAgent):
    """``bev-ngram``: hashed character n-gram language encoder, baseline phrasings only."""

    name = "bev-ngram"
    checkpoint = str(CHECKPOINTS / "bev-ngram.npz")  # the shipped exact file, never one in the cwd


class NgramAugAgent(LearnedAgent):
    """``bev-ngram-aug``: as ``bev-ngram``, trained with ``--augment-instructions``."""

    name = "bev-ngram-aug"
    checkpoint = str(CHECKPOINTS / "bev-ngram-aug.npz")  # the shipped exact file, never one in the cwd


class MinilmAgent(LearnedAgent):
    """``bev-minilm``: the frozen pretrained sentence encoder all-MiniLM-L6-v2
    (:mod:`icrsumo.learn.minilm`) through an MLP, baseline phrasings only."""

    name = "bev-minilm"
    checkpoint = str(CHECKPOINTS / "bev-minilm.npz")  # the shipped exact file, never one in the cwd

    @classmethod
    def check_ready(cls) -> None:
        """Read the checkpoint and load the sentence encoder and its tokenizer: the InputErrors
        a worker would meet (a missing ``tokenizers`` library, a missing or damaged file),
        raised before any episode runs (``icrsumo evaluate`` calls it). Only the agents that
        need the encoder have it, so the other learned agents add nothing to start-up."""
        from .minilm import encoder

        read_checkpoint(checkpoint_path(cls.checkpoint))
        encoder()


class MinilmAugAgent(MinilmAgent):
    """``bev-minilm-aug``: as ``bev-minilm``, trained with ``--augment-instructions``."""

    name = "bev-minilm-aug"
    checkpoint = str(CHECKPOINTS / "bev-minilm-aug.npz")  # the shipped exact file, never one in the cwd
