"""Batched inference for an evaluation (``--batch-inference DEVICE``): the inference processes
of each non-privileged agent (:mod:`icrsumo.agents.hosting.batched`) and the jobs that use them."""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any

from icrsumo.core.errors import visible

from .options import EvalOptions
from .plan import Job


def start_inference(opts: EvalOptions, todo: list[Job], factories: Mapping[str, Callable]) -> dict[str, Any]:
    """The inference processes of every non-privileged agent spec of ``todo`` (spec ->
    :class:`icrsumo.agents.hosting.batched.ServerGroup`) when ``opts.batch_inference`` is set."""
    if opts.batch_inference is None or not todo:
        return {}
    from icrsumo.agents.hosting.batched import start_group

    servers: dict[str, Any] = {}
    try:
        for spec in dict.fromkeys(j.agent_spec for j in todo):
            if not getattr(factories[spec], "privileged", False):
                servers[spec] = start_group(spec, opts.batch_inference, opts.max_batch,
                                            opts.inference_processes, factory=factories[spec])
    except BaseException:
        for server in servers.values():
            server.stop()
        raise
    return servers


def route_jobs(jobs: list[Job], servers: Mapping[str, Any]) -> list[Job]:
    """``jobs`` with the agents that have inference processes reached through them: their job
    carries the group's picklable factory (the sockets, the name and the key)."""
    factories = {spec: group.factory() for spec, group in servers.items()}
    return [replace(j, factory=factories[j.agent_spec]) if j.agent_spec in factories else j for j in jobs]


def stop_inference(opts: EvalOptions, servers: Mapping[str, Any]) -> dict[str, dict]:
    """Stop the inference processes; returns agent name -> their statistics (named on stderr
    unless ``opts.quiet``)."""
    stats: dict[str, dict] = {}
    for server in servers.values():
        s = server.stop()
        if s:
            stats[server.name] = s
        if s and not opts.quiet:
            print(f"icrsumo: batched inference of {visible(server.name)} on {opts.batch_inference} "
                  f"({s['processes']} process{'es' if s['processes'] > 1 else ''}): "
                  f"{s['acts']} actions in {s['batches']} forward passes (mean batch "
                  f"{s['acts'] / max(s['batches'], 1):.1f}, largest {s['largest_batch']})",
                  file=sys.stderr)
    return stats
