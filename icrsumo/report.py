"""Reports of an evaluation: ICR-Drive tables (Markdown, CSV, LaTeX), figures, the leaderboard
results files (as the run's scoring writes them, :mod:`icrsumo.scoring`). The only module that
uses matplotlib (imported lazily, Agg, no pyplot)."""

from __future__ import annotations

import csv
import functools
import io
import re
import sys
import textwrap
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .aggregate import BASELINE, EPISODE_COLUMNS, episode_table
from .errors import visible
from .fsio import MAX_FILE_NAME, bounded_name, dumps_json, write_atomic
from .scoring import DEFAULT_SCORING, get_scoring
from .types import EpisodeLog, EpisodeRecord
from .vocab import EventKind, Family

# --------------------------------------------------------------------------- tables
_HEADER = ("Agent", "Family", "DS", "RC", "IS", "ΔDS [95% CI]", "ΔRC [95% CI]", "ΔIS", "worst ΔDS",
           "RD %", "TO %", "n", "crashed")
_CSV_HEADER = ("agent", "family", "n", "n_routes", "DS", "RC", "IS", "dDS", "dDS_ci95_lo", "dDS_ci95_hi",
               "dRC", "dRC_ci95_lo", "dRC_ci95_hi", "dIS", "worst_dDS", "RD_pct", "TO_pct",
               "baseline_done_variant_failed", "n_crashed", "unpaired", "base_DS", "base_RC", "base_IS")


#: the column an evaluation with a language-model agent adds (icrsumo.agents.llm)
_ANSWERS_HEADER = "invalid %"
_ANSWERS_CSV = ("model_calls", "invalid_answers", "invalid_rate")


def has_answers(summary: dict) -> bool:
    """Whether an agent of ``summary`` asked a language model (its rows carry invalid_rate)."""
    return any("invalid_rate" in a["baseline"] for a in summary["agents"].values())


def _answer_cell(b: dict, none: str) -> str:
    return _pct(b.get("invalid_rate"), none)


def _rows(summary: dict) -> list[tuple[str, str, dict]]:
    """(agent, family, block) for every table row: the baseline row first, then each family."""
    out = []
    for agent, a in summary["agents"].items():
        out.append((agent, BASELINE, a["baseline"]))
        for fam, block in a["families"].items():
            out.append((agent, fam, block))
    return out


def _num(x: float | None, nd: int, sign: bool = False, none: str = "—") -> str:
    if x is None:
        return none
    s = f"{x:+.{nd}f}" if sign else f"{x:.{nd}f}"
    return s.lstrip("+-") if float(s) == 0.0 else s


def _pct(x: float | None, none: str) -> str:
    return none if x is None else f"{100.0 * x:.1f}"


def _ci(ci: Sequence[float] | None, none: str) -> str:
    return none if ci is None else f"[{ci[0]:.1f}, {ci[1]:.1f}]"


def _cells(fam: str, b: dict, none: str) -> list[str]:
    cells = [_num(b["DS"], 1, none=none), _num(b["RC"], 1, none=none), _num(b["IS"], 3, none=none)]
    if fam == BASELINE:
        cells += [none] * 4
    else:
        cells += [
            f"{_num(b['dDS'], 1, True, none)} {_ci(b['dDS_ci95'], '')}".strip(),
            f"{_num(b['dRC'], 1, True, none)} {_ci(b['dRC_ci95'], '')}".strip(),
            _num(b["dIS"], 3, True, none),
            _num(b["worst_dDS"], 1, True, none),
        ]
    return cells + [_pct(b["RD"], none), _pct(b["TO"], none), str(b["n"]), str(b.get("n_crashed", 0))]


def crash_note(summary: dict) -> str:
    """The line under a table that says what crashed episodes did to it ("" when none did)."""
    crashed = summary["episodes"]["crashed"]
    if not crashed:
        return ""
    unpaired = sum(f.get("unpaired", 0) for a in summary["agents"].values() for f in a["families"].values())
    also = (f"; {unpaired} finished variant episodes whose baseline crashed are left out too"
            if unpaired else "")
    return (f"{crashed} episode{'s' * (crashed != 1)} crashed and {'are' if crashed != 1 else 'is'} left "
            f"out: each family's row covers only its complete pairs (variant and baseline both finished; "
            f"n counts them){also}. `icrsumo evaluate --retry-crashed` runs the crashed ones again.")


_TEX_SPECIAL = {"\\": r"\textbackslash{}", "~": r"\textasciitilde{}", "^": r"\^{}",
                **{c: "\\" + c for c in "&%$#_{}"}}


def md_cell(s: str) -> str:
    """``s`` safe in a Markdown table cell: one line, ``|`` escaped, control characters written
    out (:func:`icrsumo.errors.visible`). Every Markdown table of a name or a text uses it."""
    return visible(" ".join(str(s).split())).replace("|", "\\|")


def tex_escape(s: str) -> str:
    """``s`` safe in LaTeX: one line, control characters written out
    (:func:`icrsumo.errors.visible`), then LaTeX's special characters escaped."""
    return "".join(_TEX_SPECIAL.get(c, c) for c in visible(" ".join(str(s).split())))


def _tex_num(cell: str) -> str:
    """Numeric cell text to LaTeX: "-" as a math minus, "—" (no data) as "--"."""
    return cell.replace("−", "-").replace("-", "$-$").replace("—", "--")


#: first characters that make a spreadsheet read a CSV cell as a formula
_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def csv_cell(v: Any) -> Any:
    """A CSV value that a spreadsheet never runs: a text starting with = + - @ (or a tab or
    carriage return) that is not a number gets a leading apostrophe; None is empty."""
    if v is None:
        return ""
    if isinstance(v, str) and v.startswith(_FORMULA_START):
        try:
            float(v)
        except ValueError:
            return "'" + v
    return v


def _csv_text(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for row in rows:
        w.writerow([csv_cell(v) for v in row])
    return buf.getvalue()


def table_cells(summary: dict) -> tuple[tuple[str, ...], list[tuple[str, str, list[str]]]]:
    """The results table as text cells: its header and one (agent, family, cells) per row, as
    the markdown table shows them."""
    if has_answers(summary):
        return (*_HEADER, _ANSWERS_HEADER), [(agent, fam, [*_cells(fam, b, "—"), _answer_cell(b, "—")])
                                             for agent, fam, b in _rows(summary)]
    return _HEADER, [(agent, fam, _cells(fam, b, "—")) for agent, fam, b in _rows(summary)]


def tables(summary: dict) -> dict[str, str]:
    """The ICR-Drive Table 1 layout as {"md", "csv", "tex"}: one row per (agent, family), the
    baseline row first per agent. Markdown/LaTeX show DS, RC, deltas with 1 decimal, IS with 3,
    RD/TO in % of the family's episodes; CSV has the unrounded summary numbers."""
    rows = _rows(summary)
    answers = has_answers(summary)
    header, text_rows = table_cells(summary)
    md = ["| " + " | ".join(header) + " |", "|" + "|".join(["---"] * 2 + ["---:"] * (len(header) - 2)) + "|"]
    for agent, fam, cells in text_rows:
        md.append("| " + " | ".join([md_cell(agent), fam, *cells]) + " |")
    note = crash_note(summary)
    if note:
        md += ["", note]

    csv_rows = []
    for agent, fam, b in rows:
        base = fam == BASELINE
        ci_ds = b.get("dDS_ci95") or [None, None]
        ci_rc = b.get("dRC_ci95") or [None, None]
        csv_rows.append([
            agent, fam, b["n"], None if base else b["n_routes"], b["DS"], b["RC"], b["IS"],
            b.get("dDS"), ci_ds[0], ci_ds[1], b.get("dRC"), ci_rc[0], ci_rc[1], b.get("dIS"),
            b.get("worst_dDS"),
            None if b["RD"] is None else round(100.0 * b["RD"], 2),
            None if b["TO"] is None else round(100.0 * b["TO"], 2),
            None if base else b["baseline_done_variant_failed"], b.get("n_crashed", 0),
            None if base else b.get("unpaired", 0), None if base else b.get("base_DS"),
            None if base else b.get("base_RC"), None if base else b.get("base_IS"),
        ] + ([b.get(c) for c in _ANSWERS_CSV] if answers else []))

    tex_head = ["Agent", "Family", "DS", "RC", "IS", r"$\Delta$DS [95\% CI]", r"$\Delta$RC [95\% CI]",
                r"$\Delta$IS", r"worst $\Delta$DS", r"RD \%", r"TO \%", "n", "crashed"]
    tex_head += [r"invalid \%"] if answers else []
    tex = [r"\begin{tabular}{ll" + "r" * (len(tex_head) - 2) + "}", r"\toprule",
           " & ".join(tex_head) + r" \\", r"\midrule"]
    prev = None
    for agent, fam, text in text_rows:
        if prev is not None and agent != prev:
            tex.append(r"\midrule")
        cells = [tex_escape(agent) if agent != prev else "", tex_escape(fam)]
        cells += [_tex_num(c) for c in text]
        tex.append(" & ".join(cells) + r" \\")
        prev = agent
    tex += [r"\bottomrule", r"\end{tabular}"]
    if note:
        tex.append("% " + note)

    csv_header = (*_CSV_HEADER, *_ANSWERS_CSV) if answers else _CSV_HEADER
    return {"md": "\n".join(md) + "\n", "csv": _csv_text(csv_header, csv_rows), "tex": "\n".join(tex) + "\n"}


_STATS_HEADER = ("Agent", "Family", "routes", "ΔDS", "rel. drop DS %", "rel. drop RC %", "p (Holm)",
                 "p (raw)", "flips lost", "flips gained")
_STATS_CSV = ("agent", "family", "n_routes", "dDS", "pdr_DS", "pdr_RC", "p_value", "p_value_raw",
              "flips_lost", "flips_gained")


def _p(x: float | None) -> str:
    return "—" if x is None else ("< 0.001" if x < 0.001 else f"{x:.3f}")


def statistics_tables(summary: dict) -> dict[str, str]:
    """What a reviewer asks for beside Δ and its CI, per agent and family, as {"md", "csv"}: the
    routes paired, ΔDS, the relative drops of DS and RC (%), the Wilcoxon signed-rank p-value of
    the per-route ΔDS (Holm-corrected over the agent's families, and raw), and the flips of
    termination between baseline and variant (pairs that lost / gained a completed route)."""
    md = ["| " + " | ".join(_STATS_HEADER) + " |", "|" + "|".join(["---"] * 2 + ["---:"] * 8) + "|"]
    rows = []
    for agent, a in summary["agents"].items():
        for fam, b in a["families"].items():
            flips = b.get("flips") or {"lost": None, "gained": None}
            pdr = [None if b.get(k) is None else 100.0 * b[k] for k in ("pdr_DS", "pdr_RC")]
            md.append("| " + " | ".join([
                md_cell(agent), fam, str(b["n_routes"]), _num(b.get("dDS"), 1, True), _num(pdr[0], 1),
                _num(pdr[1], 1), _p(b.get("p_value")), _p(b.get("p_value_raw")),
                str(flips["lost"]), str(flips["gained"])]) + " |")
            rows.append([agent, fam, b["n_routes"], b.get("dDS"), b.get("pdr_DS"), b.get("pdr_RC"),
                         b.get("p_value"), b.get("p_value_raw"), flips["lost"], flips["gained"]])
    return {"md": "\n".join(md) + "\n", "csv": _csv_text(_STATS_CSV, rows)}


_OUTCOMES = ("followed_route", "followed_text", "other", "not_reached")


def attribution_table(summary: dict, doc: dict, top: int = 20) -> str:
    """Markdown: per agent and family the decisions' outcomes, compliance under a contradicting
    text and adherence to the route; then the ``top`` templates by the flips they were active
    at (first-divergence attribution)."""
    md = ["| Agent | Family | followed route | followed text | other | not reached | compliance % | "
          "adherence % |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for agent, a in summary["agents"].items():
        for fam, b in [(BASELINE, a["baseline"]), *a["families"].items()]:
            d = b.get("decisions")
            if d is None:
                continue
            comp = None if b.get("compliance") is None else 100.0 * b["compliance"]
            adh = None if b.get("adherence") is None else 100.0 * b["adherence"]
            md.append("| " + " | ".join([md_cell(agent), fam, *(str(d[o]) for o in _OUTCOMES), _num(comp, 1),
                                         _num(adh, 1)]) + " |")
    md += ["", f"Flips (a variant failed where its baseline completed): {len(doc['flips'])}. "
               f"Templates and noise operations active at the decision where the ego left the route "
               f"(top {top}):", "",
           "| Family | Template | flips | uses | flip rate % | example |", "|---|---|---:|---:|---:|---|"]
    for r in doc["templates"][:top]:
        rate = None if r["flip_rate"] is None else 100.0 * r["flip_rate"]
        md.append(f"| {r['family']} | {md_cell(r['template'])} | {r['flips']} | {r['uses']} | "
                  f"{_num(rate, 1)} | {md_cell(r['example'])} |")
    md += ["", "Every flip: the decision where the ego left the route and the instruction active there.",
           "", "| Agent | Route | Family | k | ended | decision | route wanted | driven | instruction | "
           "template |",
           "|---|---|---|---:|---|---|---|---|---|---|"]
    for f in doc["flips"]:
        d, ins = f.get("decision") or {}, f.get("instruction") or {}
        where = f"{d['kind']} at {d['pos']:.0f} m" if d else "—"
        cells = [f["agent"], f["route_id"], f["family"], str(f["k"]), f["termination"], where,
                 d.get("route_intent", "—"), d.get("executed") or d.get("outcome", "—"),
                 ins.get("text", "—"), ins.get("template", "—")]
        md.append("| " + " | ".join(md_cell(c) for c in cells) + " |")
    return "\n".join(md) + "\n"


# --------------------------------------------------------------------------- figures
def plain_text(draw: Callable[..., None]) -> Callable[..., None]:
    """Draw a figure with mathtext off: names and texts in it are data, so a "$" in an agent
    name or an instruction is a dollar sign, never the start of a formula that fails to parse."""
    @functools.wraps(draw)
    def wrapped(*args: Any, **kwargs: Any) -> None:
        import matplotlib

        with matplotlib.rc_context({"text.parse_math": False}):
            draw(*args, **kwargs)

    return wrapped


@plain_text
def confusion_heatmaps(summary: dict, agent: str, path: Path) -> None:
    """One heatmap per family (baseline first) of ``agent``: instructed intent (rows) x executed
    branch (columns), counts of reached decisions."""
    a = summary["agents"][agent]
    blocks = [(BASELINE, a["baseline"]), *a["families"].items()]
    blocks = [(f, b) for f, b in blocks if b.get("confusion")]
    if not blocks:
        return
    rows = sorted({t for _, b in blocks for t in b["confusion"]})
    cols = sorted({e for _, b in blocks for c in b["confusion"].values() for e in c})
    fig = _figure(2.6 * len(blocks) + 1.0, 0.35 * len(rows) + 2.2)
    for i, (fam, b) in enumerate(blocks):
        ax = fig.add_subplot(1, len(blocks), i + 1)
        grid = [[b["confusion"].get(r, {}).get(c, 0) for c in cols] for r in rows]
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
    _save(fig, path)


@plain_text
def template_flip_bars(doc: dict, path: Path, top: int = 15) -> None:
    """Bars of the ``top`` templates by flips, labelled with their flip rate."""
    rows = doc["templates"][:top]
    if not rows:
        return
    fig = _figure(7.5, 0.32 * len(rows) + 1.6)
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
    _save(fig, path)


def _figure(width: float, height: float):
    import sys

    import matplotlib

    if "matplotlib.pyplot" not in sys.modules:  # never switch a backend someone else uses
        matplotlib.use("Agg")
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), dpi=100)


def _save(fig, path: Path) -> None:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", metadata={"Software": None})
    write_atomic(Path(path), buf.getvalue())


_FAMILY_MARKERS = {BASELINE: "o", Family.PARAPHRASE: "s", Family.AMBIGUITY: "^", Family.NOISE: "D",
                   Family.MISLEADING: "v"}


def _agent_colours(agents: Sequence[str]) -> dict[str, Any]:
    from matplotlib import colormaps

    cmap = colormaps["tab10"]
    return {a: cmap(i % 10) for i, a in enumerate(agents)}


@plain_text
def rd_to_plane(summary: dict, path: Path) -> None:
    """Scatter of the failure split: x = TO share, y = RD share (% of episodes), one point per
    (agent, family): colour = agent, marker = family (baseline hollow), both in legends (points
    that coincide stay readable: no text on the plot)."""
    from matplotlib.lines import Line2D

    fig = _figure(7.5, 6.0)
    ax = fig.add_subplot()
    colours = _agent_colours(list(summary["agents"]))
    top = 0.0
    families: list[str] = []
    for agent, fam, b in _rows(summary):
        if b["RD"] is None or b["TO"] is None:
            continue
        x, y = 100.0 * b["TO"], 100.0 * b["RD"]
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
    ax.set_title(f"Failure split, suite {visible(str(summary.get('suite', '')))}", fontsize=12)
    ax.grid(True, color="0.92", zorder=0)
    agent_handles = [Line2D([], [], color=c, marker="o", linestyle="", markersize=8, label=visible(a))
                     for a, c in colours.items()]
    fam_handles = [Line2D([], [], color="0.3", marker=_FAMILY_MARKERS.get(f, "P"), linestyle="", markersize=8,
                          markerfacecolor="none" if f == BASELINE else "0.3", label=f) for f in families]
    first = ax.legend(handles=agent_handles, title="agent", fontsize=9, title_fontsize=9, loc="upper right")
    ax.add_artist(first)
    ax.legend(handles=fam_handles, title="family", fontsize=9, title_fontsize=9, loc="center right")
    fig.tight_layout()
    _save(fig, path)


@plain_text
def delta_bars(summary: dict, path: Path) -> None:
    """Two panels (ΔDS, ΔRC): per family, one bar per agent with its 95 % bootstrap CI."""
    agents = list(summary["agents"])
    fams = list(summary.get("families") or next(iter(summary["agents"].values()), {}).get("families", {}))
    colours = _agent_colours(agents)
    fig = _figure(max(6.0, 1.6 * len(fams) + 2.0), 6.5)
    axes = fig.subplots(2, 1, sharex=True)
    width = 0.8 / max(1, len(agents))
    x0 = np.arange(len(fams), dtype=float)
    for ax, metric in zip(axes, ("DS", "RC")):
        for i, agent in enumerate(agents):
            vals, lo, hi = [], [], []
            for fam in fams:
                b = summary["agents"][agent]["families"].get(fam, {})
                d, ci = b.get(f"d{metric}"), b.get(f"d{metric}_ci95")
                vals.append(np.nan if d is None else d)
                lo.append(0.0 if d is None or ci is None else max(0.0, d - ci[0]))
                hi.append(0.0 if d is None or ci is None else max(0.0, ci[1] - d))
            xs = x0 - 0.4 + width * (i + 0.5)
            ax.bar(xs, vals, width=width * 0.95, color=colours[agent], label=visible(agent),
                   yerr=np.array([lo, hi]), capsize=3, error_kw={"elinewidth": 1.0})
        ax.axhline(0.0, color="0.3", lw=0.8)
        ax.set_axisbelow(True)
        ax.set_ylabel(f"Δ{metric} vs baseline")
        ax.grid(True, axis="y", color="0.92")
    suite = visible(str(summary.get("suite", "")))
    axes[0].set_title(f"Paired deltas with 95 % route-bootstrap CI, suite {suite}")
    axes[1].set_xticks(x0)
    axes[1].set_xticklabels(fams)
    if agents:
        axes[0].legend(fontsize=8, loc="best")
    fig.tight_layout()
    _save(fig, path)


#: what the rollout figure writes where an episode ended
_ENDED = {"completed": "done", "route_deviation": "route deviation", "route_timeout": "timeout",
          "agent_blocked": "blocked", "stuck": "stuck", "sim_error": "simulator error"}
#: events the rollout figure marks (the penalised ones)
_DRAWN_EVENTS = (EventKind.COLLISION_PEDESTRIAN, EventKind.COLLISION_VEHICLE, EventKind.COLLISION_STATIC,
                 EventKind.RED_LIGHT, EventKind.STOP_SIGN)


@plain_text
def paired_rollout(net, baseline_log: EpisodeLog, variant_logs: list[tuple[str, EpisodeLog, str]],
                   baseline_text: str, path: Path, title: str = "") -> None:
    """The map's lanes around the trajectories (bounding box + 30 m), the route, the baseline
    trajectory (wide, underneath) and each counterfactual one (``(label, log, instruction
    text)``) with start (o) and end (X, with why it ended) markers and its penalised events (*),
    and the instruction texts as captions under the map, coloured like their lines."""
    from matplotlib import colormaps
    from matplotlib.collections import LineCollection

    trajs = [("baseline", baseline_log, baseline_text, "black")]
    cmap = colormaps["tab10"]
    for i, (label, log, text) in enumerate(variant_logs):
        trajs.append((label, log, text, cmap(i % 10)))

    pts = [np.column_stack([log.x, log.y]) for _, log, _, _ in trajs if len(log.x)]
    if pts:
        allp = np.concatenate(pts)
        lo, hi = allp.min(axis=0) - 30.0, allp.max(axis=0) + 30.0
    else:
        shapes = list(net.lane_shape.values())
        allp = np.concatenate(shapes) if shapes else np.zeros((1, 2))
        lo, hi = allp.min(axis=0), allp.max(axis=0)

    caption = [("baseline", baseline_text, "black")] + [(lab, txt, c) for lab, _, txt, c in trajs[1:]]
    wrapped = [textwrap.wrap(visible(f"{lab}: {txt}"), 95) or [f"{lab}:"] for lab, txt, _ in caption]
    n_lines = sum(len(w) for w in wrapped)
    fig_w, map_w, map_h, line_h = 7.5, 6.6, 5.6, 0.2  # inches
    cap_h = 0.2 + line_h * n_lines
    total_h = cap_h + 0.65 + map_h + 0.45  # captions, x label, map, title
    fig = _figure(fig_w, total_h)
    ax = fig.add_axes([0.09, (cap_h + 0.65) / total_h, map_w / fig_w, map_h / total_h])
    # widen the box's short side so that, at equal aspect, the map fills the axes
    span = hi - lo
    want = map_w / map_h
    if span[0] / max(span[1], 1e-9) < want:
        pad = (want * span[1] - span[0]) / 2.0
        lo, hi = lo - [pad, 0.0], hi + [pad, 0.0]
    else:
        pad = (span[0] / want - span[1]) / 2.0
        lo, hi = lo - [0.0, pad], hi + [0.0, pad]
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
    for label, log, _, colour in trajs:
        if not len(log.x):
            continue
        x, y = np.asarray(log.x), np.asarray(log.y)
        base = label == "baseline"  # drawn wide underneath: an identical variant cannot hide it
        ax.plot(x, y, color=colour, lw=4.0 if base else 1.4, label=label, zorder=2 if base else 3,
                alpha=0.45 if base else 0.9)
        ax.plot(x[0], y[0], "o", color=colour, ms=6, zorder=4)
        ax.plot(x[-1], y[-1], "X", color=colour, ms=8, zorder=4)
        ax.annotate(_ENDED.get(str(log.termination), str(log.termination)), (x[-1], y[-1]), xytext=(5, -10),
                    textcoords="offset points", fontsize=8, color=colour, zorder=5)
        for ev in log.events:
            if ev.kind in _DRAWN_EVENTS and (ev.x or ev.y):
                ax.plot(ev.x, ev.y, "*", color=colour, ms=11, mec="black", mew=0.5, zorder=5)
                ax.annotate(str(ev.kind).replace("_", " "), (ev.x, ev.y), xytext=(5, 4),
                            textcoords="offset points", fontsize=7, color=colour, zorder=5)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(fontsize=7, loc="best")
    if title:
        ax.set_title(visible(title))
    yy = cap_h / total_h
    for (_, _, colour), lines in zip(caption, wrapped):
        for line in lines:
            fig.text(0.03, yy, line, color=colour, fontsize=8, va="top", ha="left")
            yy -= line_h / total_h
    _save(fig, path)


# --------------------------------------------------------------------------- all of it
def _file_name(s: str) -> str:
    """The part of a file name that stands for ``s`` (an agent name, a family): letters,
    digits and ``_.-`` kept, the rest ``_``, at most half of
    :data:`icrsumo.fsio.MAX_FILE_NAME` characters (a longer name is cut and ends with a hash of it)."""
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", s)
    name = name if name not in ("", ".", "..") else f"x_{name}"
    return bounded_name(name, s, MAX_FILE_NAME // 2)


def figure_or_note(draw: Any, *args: Any) -> None:
    """``draw(*args)`` (the last argument is the figure's path); a figure that fails is a note
    on stderr naming it, never the end of a run whose numbers are all in the tables. A full
    disk or a missing folder still raises (the tables would fail the same way)."""
    try:
        draw(*args)
    except OSError:
        raise
    except Exception as err:  # noqa: BLE001 - matplotlib's many ways to fail on odd text
        print(f"icrsumo: note: no figure {Path(args[-1]).name}: {type(err).__name__}: "
              f"{visible(' '.join(str(err).split())[:160])}", file=sys.stderr)


@plain_text
def guard_tradeoff(doc: dict, path: Path) -> None:
    """Detection (misleading instructions blocked, %) against false blocks (baseline, paraphrase
    and noise instructions blocked, %), one point per guard (pooled over its rows), labelled."""
    fig = _figure(4.6, 3.8)
    ax = fig.add_subplot()
    for i, (name, g) in enumerate(sorted(doc["guards"].items())):
        if g["detection"] is None or g["false_blocks"] is None:
            continue
        x, y = 100 * g["false_blocks"], 100 * g["detection"]
        ax.scatter([x], [y], s=40, color=f"C{i % 10}", zorder=3)
        right = x > 60  # the label inside the axes, beside its point
        ax.annotate(visible(name), (x, y), textcoords="offset points", xytext=(-7 if right else 7, 0),
                    ha="right" if right else "left", va="center", fontsize=8)
    ax.set_xlim(-2, 102)
    ax.set_ylim(-2, 102)
    ax.set_xlabel("false blocks: baseline, paraphrase, noise (%)")
    ax.set_ylabel("detection: misleading blocked (%)")
    ax.set_title("Instruction guards: what they catch, what they wrongly block", fontsize=9)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    _save(fig, path)


def write_guard(doc: dict, out_dir: Path) -> None:
    """Write guard.json, guard.md and figures/guard_tradeoff.png of a guard document
    (:func:`icrsumo.guards.measure.guard_doc`)."""
    from .guards.measure import guard_markdown

    out = Path(out_dir)
    write_atomic(out / "guard.json", dumps_json(doc))
    write_atomic(out / "guard.md", guard_markdown(doc, md_cell))
    figure_or_note(guard_tradeoff, doc, out / "figures" / "guard_tradeoff.png")


def write_attribution(summary: dict, doc: dict, out_dir: Path) -> None:
    """Write attribution.json (flips and template ranking), attribution.md,
    figures/confusion_<agent>.png and figures/template_flips.png."""
    out = Path(out_dir)
    write_atomic(out / "attribution.json", dumps_json(doc))
    write_atomic(out / "attribution.md", attribution_table(summary, doc))
    for agent in summary["agents"]:
        path = out / "figures" / f"confusion_{_file_name(agent)}.png"
        figure_or_note(confusion_heatmaps, summary, agent, path)
    figure_or_note(template_flip_bars, doc, out / "figures" / "template_flips.png")


def write_report(summary: dict, records: Sequence[EpisodeRecord], out_dir: Path,
                 ends: dict | None = None) -> str:
    """Write summary.json, results.{md,csv,tex}, statistics.{md,csv}, episodes.csv, figures/rd_to.png,
    figures/delta_bars.png and leaderboard/<agent>_<family>.json (baseline included) under
    ``out_dir``; returns the Markdown table. ``ends``: the episodes' log facts for episodes.csv
    (:func:`icrsumo.aggregate.episode_table`); paired rollout figures are written by the caller."""
    out = Path(out_dir)
    write_atomic(out / "summary.json", dumps_json(summary))
    t = tables(summary)
    write_atomic(out / "results.md", t["md"])
    write_atomic(out / "results.csv", t["csv"])
    write_atomic(out / "results.tex", t["tex"])
    st = statistics_tables(summary)
    write_atomic(out / "statistics.md", st["md"])
    write_atomic(out / "statistics.csv", st["csv"])
    rows = episode_table(records, ends)
    write_atomic(out / "episodes.csv", _csv_text(EPISODE_COLUMNS, ([row[c] for c in EPISODE_COLUMNS]
                                                                    for row in rows)))
    figure_or_note(rd_to_plane, summary, out / "figures" / "rd_to.png")
    figure_or_note(delta_bars, summary, out / "figures" / "delta_bars.png")
    fams = [BASELINE] + list(summary.get("families") or [])
    checkpoint = get_scoring(summary.get("scoring", DEFAULT_SCORING)).leaderboard_file
    for agent in summary["agents"]:
        for fam in fams:
            cp = checkpoint(records, agent, fam)
            if cp["_checkpoint"]["records"]:
                write_atomic(out / "leaderboard" / f"{_file_name(agent)}_{_file_name(fam)}.json",
                             dumps_json(cp))
    return t["md"]
