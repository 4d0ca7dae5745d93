"""Side effects of an episode as callbacks that attach to the loop (:mod:`icrsumo.sim.episode`).

The loop calls every attached callback at fixed points; a callback overrides the hooks it
needs (the base class's do nothing). Built in: :class:`LogRecorder` (the episode log's columns
and events; every episode has one), :class:`LoopTimer` (wall-clock split into
:class:`LoopTimings`, for ``tools/benchmark.py``) and :class:`VideoRecorder` (the agent's view
with its instruction as a video). Not a callback: :class:`PhaseClock`, the loop's wall time
split into phases when one is given to it (``tools/benchmark.py --protocol``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

from icrsumo.core.types import Event

if TYPE_CHECKING:
    from icrsumo.agents.base import Action, Observation

    from .episode import Episode


class StepRecord(NamedTuple):
    """One recorded simulation step: time ``t`` (s), ego centre ``x``/``y`` (m), ``yaw`` (rad),
    ``speed`` (m/s), route ``progress`` (m), active ``instruction`` id (-1 none), ``outside``
    (OutsideRouteLanesTest's bits, see :class:`~icrsumo.core.types.EpisodeLog`), ``route_dist`` (m),
    the step's ``events``, ``traffic_speed`` (m/s, mean of the other vehicles, -1 none) and
    ``speed_limit`` (m/s, of the nearest driving lane)."""

    t: float
    x: float
    y: float
    yaw: float
    speed: float
    progress: float
    instruction: int
    outside: int
    route_dist: float
    events: tuple[Event, ...]
    traffic_speed: float = -1.0
    speed_limit: float = 0.0


class EpisodeCallback:
    """Hooks of the closed loop, in call order: ``on_start`` (before SUMO starts),
    ``on_ready`` (SUMO warmed up, the ego inserted), then per simulation step ``on_step``, per
    agent decision ``on_render_start`` / ``on_render_end`` (the BEV raster), ``on_observation``,
    ``on_act_start`` / ``on_act_end`` (when :func:`~icrsumo.sim.episode.run_episode` calls the
    agent), and once ``on_end`` (the episode ended) and ``on_close`` (SUMO closed)."""

    def on_start(self, episode: Episode) -> None: ...

    def on_ready(self, episode: Episode) -> None: ...

    def on_step(self, episode: Episode, step: StepRecord) -> None: ...

    def on_render_start(self, episode: Episode) -> None: ...

    def on_render_end(self, episode: Episode) -> None: ...

    def on_observation(self, episode: Episode, obs: Observation) -> None: ...

    def on_act_start(self, episode: Episode, obs: Observation) -> None: ...

    def on_act_end(self, episode: Episode, action: Action) -> None: ...

    def on_end(self, episode: Episode) -> None: ...

    def on_close(self, episode: Episode) -> None: ...


_COLUMNS = ("t", "x", "y", "yaw", "speed", "progress", "instruction", "outside", "route_dist")
#: the StepRecord fields after ``events`` that are columns too
_LATE_COLUMNS = ("traffic_speed", "speed_limit")


class LogRecorder(EpisodeCallback):
    """The episode log's per-step columns (``cols``: name -> list) and events (``events``),
    recorded step by step; the loop adds the events that end an episode off a step."""

    def __init__(self) -> None:
        self.cols: dict[str, list] = {k: [] for k in (*_COLUMNS, *_LATE_COLUMNS)}
        self.events: list[Event] = []
        self._append = [self.cols[k].append for k in _COLUMNS]

    def on_step(self, episode: Episode, step: StepRecord) -> None:
        for append, value in zip(self._append, step):
            append(value)
        self.cols["traffic_speed"].append(step.traffic_speed)
        self.cols["speed_limit"].append(step.speed_limit)
        if step.events:
            self.events += step.events

    @property
    def steps(self) -> int:
        return len(self.cols["t"])


@dataclass
class LoopTimings:
    """Wall-clock split of episodes (s, ``time.perf_counter``), filled by a :class:`LoopTimer`;
    it accumulates over the episodes it is attached to.

    ``setup_s``: SUMO start, traffic warm-up and ego insertion; ``loop_s``: the closed loop
    over ``steps`` steps (everything per step: sensors, BEV, the agent, controller, SUMO);
    ``render_s`` over ``frames`` BEV frames; ``act_s`` over ``acts`` calls of ``agent.act``.
    """

    setup_s: float = 0.0
    loop_s: float = 0.0
    steps: int = 0
    render_s: float = 0.0
    frames: int = 0
    act_s: float = 0.0
    acts: int = 0


class LoopTimer(EpisodeCallback):
    """Fills ``timings`` (:class:`LoopTimings`) from the loop's hooks."""

    def __init__(self, timings: LoopTimings) -> None:
        self.timings = timings
        self._t0 = self._ready = self._render = self._act = 0.0

    def on_start(self, episode: Episode) -> None:
        self._t0 = time.perf_counter()
        self._ready = 0.0

    def on_ready(self, episode: Episode) -> None:
        self._ready = time.perf_counter()
        self.timings.setup_s += self._ready - self._t0

    def on_render_start(self, episode: Episode) -> None:
        self._render = time.perf_counter()

    def on_render_end(self, episode: Episode) -> None:
        self.timings.render_s += time.perf_counter() - self._render
        self.timings.frames += 1

    def on_act_start(self, episode: Episode, obs: Observation) -> None:
        self._act = time.perf_counter()

    def on_act_end(self, episode: Episode, action: Action) -> None:
        self.timings.act_s += time.perf_counter() - self._act
        self.timings.acts += 1

    def on_end(self, episode: Episode) -> None:
        if self._ready:
            self.timings.loop_s += time.perf_counter() - self._ready
        self.timings.steps += episode.recorder.steps


class PhaseClock:
    """Wall time split into phases (s, ``time.perf_counter``): :meth:`lap` gives the time
    since the previous lap (the first: since the clock was made, ``start``) to one phase
    (:class:`~icrsumo.core.vocab.Phase`), so ``phases`` add up to ``last - start``. The loop
    laps only when it is given one (``run_episode(..., clock=)``, for ``EvalOptions.profile``);
    its episodes are the same with or without. ``steps``: the episode's steps, set by the
    caller."""

    __slots__ = ("phases", "start", "last", "steps")

    def __init__(self) -> None:
        self.phases: dict[str, float] = {}
        self.start = self.last = time.perf_counter()
        self.steps = 0

    def lap(self, phase: str) -> None:
        """The time since the last lap goes to ``phase``."""
        now = time.perf_counter()
        self.phases[phase] = self.phases.get(phase, 0.0) + (now - self.last)
        self.last = now


class VideoRecorder(EpisodeCallback):
    """Writes every observation's BEV raster with its instruction, notice and speed to
    ``path`` (:class:`icrsumo.render.VideoWriter`)."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._writer = None

    def on_start(self, episode: Episode) -> None:
        from icrsumo.render import VideoWriter

        self._writer = VideoWriter(self.path)

    def on_observation(self, episode: Episode, obs: Observation) -> None:
        if self._writer is not None:
            self._writer.add(obs.bev, obs.instruction, obs.notice, obs.speed, obs.t)

    def on_close(self, episode: Episode) -> None:
        if self._writer is not None:
            writer, self._writer = self._writer, None
            writer.close()
