"""The figures of an evaluation: the RD-vs-TO plane, the deltas' bars, the decision confusion
heatmaps and the templates behind flips. The only matplotlib user with
:mod:`icrsumo.reporting.rollout` and :mod:`icrsumo.reporting.guard` (imported lazily, Agg, no
pyplot); names and texts in a figure are data (:func:`plain_text`)."""

from __future__ import annotations

import functools
import io
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from icrsumo.core.errors import note, visible
from icrsumo.core.fsio import write_atomic
from icrsumo.core.vocab import Family
from icrsumo.results.summary import BASELINE, Summary

_FAMILY_MARKERS = {BASELINE: "o", Family.PARAPHRASE: "s", Family.AMBIGUITY: "^", Family.NOISE: "D",
                   Family.MISLEADING: "v"}


def plain_text(draw: Callable[..., None]) -> Callable[..., None]:
    """Draw a figure with mathtext off: names and texts in it are data, so a "$" in an agent
    name or an instruction is a dollar sign, never the start of a formula that fails to parse."""
    @functools.wraps(draw)
    def wrapped(*args: Any, **kwargs: Any) -> None:
        import matplotlib

        with matplotlib.rc_context({"text.parse_math": False}):
            draw(*args, **kwargs)

    return wrapped


def figure(width: float, height: float):
    """A matplotlib Figure of ``width`` x ``height`` inches at 100 dpi (the Agg backend unless
    pyplot is in use: a backend someone else uses is never switched)."""
    import matplotlib

    if "matplotlib.pyplot" not in sys.modules:
        matplotlib.use("Agg")
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), dpi=100)


def save_png(fig, path: Path) -> None:
    """Write ``fig`` to ``path`` as a PNG (atomically, without the software tag)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", metadata={"Software": None})
    write_atomic(Path(path), buf.getvalue())


def figure_or_note(draw: Any, *args: Any) -> None:
    """``draw(*args)`` (the last argument is the figure's path); a figure that fails is a note
    on stderr naming it, never the end of a run whose numbers are all in the tables. A full
    disk or a missing folder still raises (the tables would fail the same way)."""
    try:
        draw(*args)
    except OSError:
        raise
    except Exception as err:  # noqa: BLE001 - matplotlib's many ways to fail on odd text
        note(f"no figure {Path(args[-1]).name}: {type(err).__name__}: {' '.join(str(err).split())[:160]}")


def _agent_colours(agents: Sequence[str]) -> dict[str, Any]:
    from matplotlib import colormaps

    cmap = colormaps["tab10"]
    return {a: cmap(i % 10) for i, a in enumerate(agents)}


def _plane_legends(ax, colours: dict[str, Any], families: list[str]) -> None:
    """The agents' (colour) and the families' (marker) legends of the RD-vs-TO plane."""
    from matplotlib.lines import Line2D

    agent_handles = [Line2D([], [], color=c, marker="o", linestyle="", markersize=8, label=visible(a))
                     for a, c in colours.items()]
    fam_handles = [Line2D([], [], color="0.3", marker=_FAMILY_MARKERS.get(f, "P"), linestyle="", markersize=8,
                          markerfacecolor="none" if f == BASELINE else "0.3", label=f) for f in families]
    first = ax.legend(handles=agent_handles, title="agent", fontsize=9, title_fontsize=9, loc="upper right")
    ax.add_artist(first)
    ax.legend(handles=fam_handles, title="family", fontsize=9, title_fontsize=9, loc="center right")


@plain_text
def rd_to_plane(summary: Summary, path: Path) -> None:
    """Scatter of the failure split: x = TO share, y = RD share (% of episodes), one point per
    (agent, family): colour = agent, marker = family (baseline hollow), both in legends (points
    that coincide stay readable: no text on the plot)."""
    fig = figure(7.5, 6.0)
    ax = fig.add_subplot()
    colours = _agent_colours(list(summary.agents))
    top = 0.0
    families: list[str] = []
    for agent, fam, b in summary.rows():
        if b.rd is None or b.to is None:
            continue
        x, y = 100.0 * b.to, 100.0 * b.rd
        top = max(top, x, y)
        marker = _FAMILY_MARKERS.get(fam, "P")
        c = colours[agent]
        ax.scatter([x], [y], s=80, marker=marker, facecolors="none" if fam == BASELINE else [c],
                   edgecolors=[c], linewidths=1.6, zorder=3, alpha=0.85)
        if fam not in families:
            families.append(fam)
    lim = max(10.0, min(100.0, top * 1.15 + 2.0))
    ax.set_xlim(-1.0, lim)
    ax.set_ylim(-1.0, lim)
    ax.plot([0, 100], [0, 100], color="0.85", lw=0.8, zorder=1)
    ax.set_xlabel("TO share (% of episodes: timeout, blocked, stuck)", fontsize=11)
    ax.set_ylabel("RD share (% of episodes: route deviation)", fontsize=11)
    ax.tick_params(labelsize=10)
    ax.set_title(f"Failure split, suite {visible(summary.suite)}", fontsize=12)
    ax.grid(True, color="0.92", zorder=0)
    _plane_legends(ax, colours, families)
    fig.tight_layout()
    save_png(fig, path)


def _bars(summary: Summary, agent: str, fams: list[str], metric: str) -> tuple[list, list, list]:
    """``agent``'s Δ``metric`` per family (NaN: none) and the error bars' lower and upper
    lengths (0 without an interval)."""
    vals, lo, hi = [], [], []
    for fam in fams:
        b = summary.agents[agent].families.get(fam)
        d = None if b is None else (b.d_ds if metric == "DS" else b.d_rc)
        ci = None if b is None else (b.d_ds_ci95 if metric == "DS" else b.d_rc_ci95)
        vals.append(np.nan if d is None else d)
        lo.append(0.0 if d is None or ci is None else max(0.0, d - ci[0]))
        hi.append(0.0 if d is None or ci is None else max(0.0, ci[1] - d))
    return vals, lo, hi


@plain_text
def delta_bars(summary: Summary, path: Path) -> None:
    """Two panels (ΔDS, ΔRC): per family, one bar per agent with its 95 % bootstrap CI."""
    agents = list(summary.agents)
    first = next(iter(summary.agents.values()), None)
    fams = list(summary.families or (first.families if first else ()))
    colours = _agent_colours(agents)
    fig = figure(max(6.0, 1.6 * len(fams) + 2.0), 6.5)
    axes = fig.subplots(2, 1, sharex=True)
    width = 0.8 / max(1, len(agents))
    x0 = np.arange(len(fams), dtype=float)
    for ax, metric in zip(axes, ("DS", "RC")):
        for i, agent in enumerate(agents):
            vals, lo, hi = _bars(summary, agent, fams, metric)
            xs = x0 - 0.4 + width * (i + 0.5)
            ax.bar(xs, vals, width=width * 0.95, color=colours[agent], label=visible(agent),
                   yerr=np.array([lo, hi]), capsize=3, error_kw={"elinewidth": 1.0})
        ax.axhline(0.0, color="0.3", lw=0.8)
        ax.set_axisbelow(True)
        ax.set_ylabel(f"Δ{metric} vs baseline")
        ax.grid(True, axis="y", color="0.92")
    axes[0].set_title(f"Paired deltas with 95 % route-bootstrap CI, suite {visible(summary.suite)}")
    axes[1].set_xticks(x0)
    axes[1].set_xticklabels(fams)
    if agents:
        axes[0].legend(fontsize=8, loc="best")
    fig.tight_layout()
    save_png(fig, path)


@plain_text
def confusion_heatmaps(summary: Summary, agent: str, path: Path) -> None:
    """One heatmap per family (baseline first) of ``agent``: instructed intent (rows) x executed
    branch (columns), counts of reached decisions."""
    blocks = [(f, b.decisions.confusion) for f, b in summary.agents[agent].blocks()
              if b.decisions is not None and b.decisions.confusion]
    if not blocks:
        return
    rows = sorted({t for _, c in blocks for t in c})
    cols = sorted({e for _, c in blocks for row in c.values() for e in row})
    fig = figure(2.6 * len(blocks) + 1.0, 0.35 * len(rows) + 2.2)
    for i, (fam, confusion) in enumerate(blocks):
        ax = fig.add_subplot(1, len(blocks), i + 1)
        grid = [[confusion.get(r, {}).get(c, 0) for c in cols] for r in rows]
        ax.imshow(grid, cmap="Blues", aspect="auto")
        for y, line in enumerate(grid):
            for x, v in enumerate(line):
                if v:
                    ax.text(x, y, str(v), ha="center", va="center", fontsize=7)
        ax.set_xticks(range(len(cols)), cols, rotation=45, ha="right", fontsize=7)
        ax.set_yticks(range(len(rows)), rows if i == 0 else [""] * len(rows), fontsize=7)
        ax.set_title(fam, fontsize=9)
        ax.set_xlabel("executed", fontsize=7)
    fig.suptitle(f"{visible(agent)}: instructed intent (rows) x executed branch", fontsize=9)
    fig.tight_layout()
    save_png(fig, path)


@plain_text
def template_flip_bars(doc: dict, path: Path, top: int = 15) -> None:
    """Bars of the ``top`` templates of an attribution document by flips, labelled with their
    flip rate."""
    rows = doc["templates"][:top]
    if not rows:
        return
    fig = figure(7.5, 0.32 * len(rows) + 1.6)
    ax = fig.add_subplot()
    labels = [visible(f"{r['family']}: {r['template']}") for r in rows][::-1]
    ax.barh(range(len(rows)), [r["flips"] for r in rows][::-1], color="tab:red")
    for y, r in enumerate(rows[::-1]):
        rate = "" if r["flip_rate"] is None else f" ({100.0 * r['flip_rate']:.0f} % of {r['uses']})"
        ax.text(r["flips"], y, f" {r['flips']}{rate}", va="center", fontsize=7)
    ax.set_yticks(range(len(rows)), labels, fontsize=7)
    ax.set_xlabel("flips: variant failed where the baseline completed")
    ax.set_title("Templates active where the ego left the route", fontsize=9)
    fig.tight_layout()
    save_png(fig, path)
