"""The paired rollout figure (``figures/rollout_<route>.png``): a route's baseline trajectory
and one counterfactual per family over the map, the instruction texts as captions."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from icrsumo.core.errors import visible
from icrsumo.core.types import EpisodeLog, EpisodeRecord
from icrsumo.results.store import ResultStore
from icrsumo.scoring import Scoring, get_scoring
from icrsumo.world.convert import safe_name
from icrsumo.world.scenario import find_scenarios, read_scenario

from .figures import figure, plain_text, save_png
from .trajectory import divergence_t

#: what the rollout figure writes where an episode ended
_ENDED = {"completed": "done", "route_deviation": "route deviation", "route_timeout": "timeout",
          "agent_blocked": "blocked", "stuck": "stuck", "sim_error": "simulator error"}
#: inches: the figure's width, the map's width and height, a caption line's height
_FIG_W, _MAP_W, _MAP_H, _LINE_H = 7.5, 6.6, 5.6, 0.2


def _extent(net, logs: list[EpisodeLog]) -> tuple[np.ndarray, np.ndarray]:
    """The trajectories' bounding box + 30 m (the whole map without a trajectory)."""
    pts = [np.column_stack([log.x, log.y]) for log in logs if len(log.x)]
    if pts:
        allp = np.concatenate(pts)
        return allp.min(axis=0) - 30.0, allp.max(axis=0) + 30.0
    shapes = list(net.lane_shape.values())
    allp = np.concatenate(shapes) if shapes else np.zeros((1, 2))
    return allp.min(axis=0), allp.max(axis=0)


def _fill(lo: np.ndarray, hi: np.ndarray, want: float) -> tuple[np.ndarray, np.ndarray]:
    """The box widened on its short side so that, at equal aspect, the map fills axes of
    aspect ``want`` (width / height)."""
    span = hi - lo
    if span[0] / max(span[1], 1e-9) < want:
        pad = (want * span[1] - span[0]) / 2.0
        return lo - [pad, 0.0], hi + [pad, 0.0]
    pad = (span[0] / want - span[1]) / 2.0
    return lo - [0.0, pad], hi + [0.0, pad]


def _draw_map(ax, net, baseline_log: EpisodeLog, lo: np.ndarray, hi: np.ndarray) -> None:
    """The lanes that reach into the box and the route."""
    from matplotlib.collections import LineCollection

    lanes = []
    for lid in sorted(net.lane_shape):
        s = net.lane_shape[lid]
        if len(s) < 2:
            continue
        smin, smax = s.min(axis=0), s.max(axis=0)
        if np.all(smax >= lo) and np.all(smin <= hi):
            lanes.append(s)
    ax.add_collection(LineCollection(lanes, colors="0.75", linewidths=0.6, zorder=1))
    if baseline_log.route:
        route = np.asarray([p[:2] for p in baseline_log.route], dtype=float)
        ax.plot(route[:, 0], route[:, 1], color="#9ecae1", lw=6, alpha=0.6, zorder=1.5, label="route",
                solid_capstyle="round")


def _draw_trajectory(ax, label: str, log: EpisodeLog, colour, scoring: Scoring) -> None:
    """One trajectory with its start, its end (and why it ended) and its penalised events; the
    baseline drawn wide underneath (an identical variant cannot hide it)."""
    if not len(log.x):
        return
    x, y = np.asarray(log.x), np.asarray(log.y)
    base = label == "baseline"
    ax.plot(x, y, color=colour, lw=4.0 if base else 1.4, label=label, zorder=2 if base else 3,
            alpha=0.45 if base else 0.9)
    ax.plot(x[0], y[0], "o", color=colour, ms=6, zorder=4)
    ax.plot(x[-1], y[-1], "X", color=colour, ms=8, zorder=4)
    ax.annotate(_ENDED.get(str(log.termination), str(log.termination)), (x[-1], y[-1]), xytext=(5, -10),
                textcoords="offset points", fontsize=8, color=colour, zorder=5)
    # the events the run's scoring penalises: a contact is logged on every step of it, and only
    # the collisions its CollisionTest counts are marked
    for ev in scoring.penalised_events(log):
        if ev.x or ev.y:
            ax.plot(ev.x, ev.y, "*", color=colour, ms=11, mec="black", mew=0.5, zorder=5)
            ax.annotate(str(ev.kind).replace("_", " "), (ev.x, ev.y), xytext=(5, 4),
                        textcoords="offset points", fontsize=7, color=colour, zorder=5)


@plain_text
def paired_rollout(net, baseline_log: EpisodeLog, variant_logs: list[tuple[str, EpisodeLog, str]],
                   baseline_text: str, path: Path, title: str = "",
                   scoring: Scoring | None = None) -> None:
    """The map's lanes around the trajectories (bounding box + 30 m), the route, the baseline
    trajectory (wide, underneath) and each counterfactual one (``(label, log, instruction
    text)``) with start (o) and end (X, with why it ended) markers and the events ``scoring``
    penalises (*; None: the default scoring's), and the instruction texts as captions under the
    map, coloured like their lines."""
    from matplotlib import colormaps

    scoring = scoring or get_scoring()
    cmap = colormaps["tab10"]
    trajs = [("baseline", baseline_log, baseline_text, "black")]
    trajs += [(label, log, text, cmap(i % 10)) for i, (label, log, text) in enumerate(variant_logs)]
    lo, hi = _extent(net, [log for _, log, _, _ in trajs])
    wrapped = [textwrap.wrap(visible(f"{lab}: {txt}"), 95) or [f"{lab}:"] for lab, _, txt, _ in trajs]
    cap_h = 0.2 + _LINE_H * sum(len(w) for w in wrapped)
    total_h = cap_h + 0.65 + _MAP_H + 0.45  # captions, x label, map, title
    fig = figure(_FIG_W, total_h)
    ax = fig.add_axes([0.09, (cap_h + 0.65) / total_h, _MAP_W / _FIG_W, _MAP_H / total_h])
    lo, hi = _fill(lo, hi, _MAP_W / _MAP_H)
    _draw_map(ax, net, baseline_log, lo, hi)
    for label, log, _, colour in trajs:
        _draw_trajectory(ax, label, log, colour, scoring)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(fontsize=7, loc="best")
    if title:
        ax.set_title(visible(title))
    yy = cap_h / total_h
    for (_, _, _, colour), lines in zip(trajs, wrapped):
        for line in lines:
            fig.text(0.03, yy, line, color=colour, fontsize=8, va="top", ha="left")
            yy -= _LINE_H / total_h
    save_png(fig, path)


def _variant(records: list[EpisodeRecord], store: ResultStore, base_log: EpisodeLog, sets: dict,
             agent: str, route: str, fam: str, seed: int) -> tuple[str, EpisodeLog, str] | None:
    """The family's drawn variant: the first that failed (else k = 0), captioned with the
    instruction active where it went wrong (where it diverged from the baseline, else where it
    ended); None without a finished one."""
    mine = sorted((r for r in records if (r.agent, r.route_id, r.family) == (agent, route, fam)
                   and r.status == "done"), key=lambda r: r.k)
    failed = [r for r in mine if r.termination_class != "done"]
    chosen = failed[0] if failed else mine[0] if mine else None  # a variant that failed, if any
    if chosen is None or (fam, chosen.k) not in sets:
        return None
    log = store.episode_log(agent, route, fam, chosen.k, seed)
    if log is None or not log.t:
        return None
    t_wrong = divergence_t(base_log, log) if failed else None
    at = t_wrong if t_wrong is not None else (log.t[-1] if failed else log.t[0])
    i = min(int(np.searchsorted(log.t, at)), len(log.t) - 1)
    iid = log.instruction[i] if failed else 0
    texts = {ins.id: ins.rendered() for ins in sets[(fam, chosen.k)].instructions}
    text = texts.get(iid, texts.get(0, ""))
    if failed:
        text = f"(active at t = {at:.1f} s, where it went wrong) {text}"
    return (f"{fam} k={chosen.k}", log, text)


def rollout_figure(out: Path, store: ResultStore, records: list[EpisodeRecord], scenarios: Path,
                   instr_dir: Path, *, route: str | None, seed: int, families: tuple[str, ...],
                   scoring: Scoring | None = None) -> None:
    """Paired rollout figure: the baseline against one variant of each of ``families`` for one
    route and agent (``route``, default the first with a finished baseline; the agent of the
    first finished baseline episode): the first variant that failed (else k = 0)."""
    from icrsumo.instructions.store import read_instruction_sets
    from icrsumo.world.networks import load_net

    done = [r for r in records if r.status == "done" and r.family == "baseline"]
    if not done:
        return
    route = route or done[0].route_id
    agent = done[0].agent
    base_log = store.episode_log(agent, route, "baseline", 0, seed)
    if base_log is None:
        return
    sets = {(s.family, s.k): s for s in read_instruction_sets(instr_dir / f"{safe_name(route)}.json")}
    variants = [v for fam in families
                if (v := _variant(records, store, base_log, sets, agent, route, fam, seed)) is not None]
    sc_dir = next((d for d in find_scenarios(scenarios) if read_scenario(d).route_id == route), None)
    if sc_dir is None:
        return
    net = load_net(read_scenario(sc_dir).net)
    fig = out / "figures" / f"rollout_{safe_name(route)}.png"
    fig.parent.mkdir(parents=True, exist_ok=True)
    paired_rollout(net, base_log, variants, sets[("baseline", 0)].instructions[0].rendered(),
                   fig, title=f"{agent} on {route}", scoring=scoring)
