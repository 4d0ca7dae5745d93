"""The simulation in three layers:

1. :mod:`~icrsumo.sim.backend` — SUMO through libsumo (the package's only libsumo importer):
   start, insert the ego, place it, step, and read a frozen :class:`~icrsumo.sim.frame.SimFrame`;
2. :mod:`~icrsumo.sim.sensors` (with :mod:`~icrsumo.sim.drivable`) — pure functions of the road
   network's geometry and a frame: route progress, infractions; no SUMO, no raster;
3. :mod:`~icrsumo.sim.episode` — the closed loop (:class:`Episode`, :func:`run_episode`) with
   side effects as :mod:`~icrsumo.sim.callbacks`.

The names below are imported on first use, so ``import icrsumo.sim`` stays light.
"""

from __future__ import annotations

from importlib import import_module

_EXPORTS = {
    "Episode": "episode", "RunOptions": "episode", "run_episode": "episode", "CONTROL_EVERY": "episode",
    "ego_route": "episode",
    "EpisodeCallback": "callbacks", "LogRecorder": "callbacks", "LoopTimer": "callbacks",
    "LoopTimings": "callbacks", "StepRecord": "callbacks", "VideoRecorder": "callbacks",
    "SimFrame": "frame", "Contact": "frame",
    "SumoBackend": "backend", "SumoSession": "backend", "SimulatorError": "backend", "EGO_ID": "backend",
    "CONTEXT_RADIUS": "backend", "sumo_constants": "backend",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'icrsumo.sim' has no attribute {name!r}")
    return getattr(import_module(f".{module}", __name__), name)
