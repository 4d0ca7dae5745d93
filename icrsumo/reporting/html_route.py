"""One route's section of report.html: the baseline and every variant over the map (an inline
SVG), one table row per episode with its instruction timeline, where, when and why it ended
and its infractions, and a map view of each agent's first divergence from its baseline."""

from __future__ import annotations

import base64
import html
import json
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from icrsumo.core.types import EpisodeLog, EpisodeRecord, InstructionSet
from icrsumo.core.vocab import Family
from icrsumo.scoring import Scoring, get_scoring

from .trajectory import divergence_t, drawn_points

#: the divergence clip: seconds before and after the divergence, seconds between frames
CLIP_BEFORE_S, CLIP_AFTER_S, CLIP_STEP_S = 1.0, 6.0, 1.0
_COLOURS = {"done": "#1a9850", "RD": "#d73027", "TO": "#fc8d59", "crashed": "#7b3294"}

Key = tuple[str, str, str, int, int]
#: (x, y, yaw) -> PNG bytes of the map view there
Render = Callable[[float, float, float], bytes]


def esc(x: object) -> str:
    """``x`` as HTML text, quotes escaped too (safe in an attribute)."""
    return html.escape(str(x), quote=True)


def _key(r: EpisodeRecord) -> Key:
    return (r.agent, r.route_id, str(r.family), r.k, r.seed)


def outcome(r: EpisodeRecord, flipped: bool) -> str:
    """The filter's outcome of an episode: crashed, flipped (failed where its baseline
    completed), failed, or completed."""
    if r.status != "done":
        return "crashed"
    if r.termination_class == "done":
        return "completed"
    return "flipped" if flipped else "failed"


class _Frame:
    """World (m) to SVG (px) for one route's map: y up in the world, down in SVG."""

    def __init__(self, xy: np.ndarray, width: float = 640.0, margin_m: float = 25.0) -> None:
        lo, hi = xy.min(axis=0) - margin_m, xy.max(axis=0) + margin_m
        self.x0, self.y1 = float(lo[0]), float(hi[1])
        span = max(float(hi[0] - lo[0]), float(hi[1] - lo[1]), 1.0)
        self.s = width / span
        self.w, self.h = (hi[0] - lo[0]) * self.s, (hi[1] - lo[1]) * self.s
        self.lo, self.hi = lo, hi

    def path(self, xy: np.ndarray) -> str:
        pts = [f"{(x - self.x0) * self.s:.1f},{(self.y1 - y) * self.s:.1f}" for x, y in xy]
        return "M" + " L".join(pts) if pts else ""

    def at(self, x: float, y: float) -> tuple[float, float]:
        return (x - self.x0) * self.s, (self.y1 - y) * self.s

    def holds(self, shape: np.ndarray) -> bool:
        return bool(np.any(np.all((shape >= self.lo) & (shape <= self.hi), axis=1)))


def _episode_svg(f: _Frame, rec: EpisodeRecord, log: EpisodeLog, out_kind: str, base: bool,
                 scoring: Scoring) -> list[str]:
    """One episode's trajectory, its end and its events."""
    colour = "#000000" if base else _COLOURS.get(str(rec.termination_class) or "crashed", "#777777")
    attrs = (f'class="ep" data-agent="{esc(rec.agent)}" data-family="{esc(rec.family)}" '
             f'data-outcome="{out_kind}"')
    label = f"{rec.agent} {rec.family} k={rec.k}: {rec.termination}, DS {rec.ds:.1f}"
    pts = drawn_points(log)
    out = [f'<g {attrs}><path d="{f.path(pts)}" stroke="{colour}" '
           f'stroke-width="{2.5 if base else 1.5}" fill="none" opacity="{1.0 if base else 0.75}">'
           f'<title>{esc(label)}</title></path>']
    if len(pts):
        ex, ey = f.at(*pts[-1])
        out.append(f'<circle cx="{ex:.1f}" cy="{ey:.1f}" r="4" fill="{colour}"><title>{esc(label)} '
                   f'— ended at t = {log.t[-1]:.1f} s, {log.progress[-1]:.0f} m along the route'
                   '</title></circle>')
    for ev in scoring.penalised_events(log):  # a contact is logged on every step of it: those counted
        if ev.x or ev.y:
            cx, cy = f.at(ev.x, ev.y)
            out.append(f'<text x="{cx:.1f}" y="{cy:.1f}" font-size="12" fill="{colour}" '
                       f'text-anchor="middle">✕<title>{esc(ev.kind)} at t = {ev.t:.1f} s, {ev.pos:.0f} m'
                       f'{(" with " + esc(ev.other)) if ev.other else ""}</title></text>')
    out.append("</g>")
    return out


def map_svg(net, logs: Sequence[tuple[EpisodeRecord, EpisodeLog, str]], base_keys: set[Key],
            scoring: Scoring | None = None) -> str:
    """The route, the lanes around it and every episode's trajectory with its end and
    infractions (the events ``scoring`` penalises, None: the default scoring's), as an inline SVG."""
    scoring = scoring or get_scoring()
    first = logs[0][1]
    route = np.asarray([p[:2] for p in first.route], dtype=float) if first.route else np.zeros((0, 2))
    every = [route] + [drawn_points(log) for _, log, _ in logs]
    xy = np.concatenate([a for a in every if len(a)]) if any(len(a) for a in every) else np.zeros((1, 2))
    f = _Frame(xy)
    out = [f'<svg class="map" viewBox="0 0 {f.w:.0f} {f.h:.0f}" width="{f.w:.0f}" height="{f.h:.0f}" '
           'xmlns="http://www.w3.org/2000/svg">',
           f'<rect width="{f.w:.0f}" height="{f.h:.0f}" fill="#f4f4f4"/>']
    if net is not None:
        lane_w = max(3.2 * f.s, 1.0)
        for lane, shape in net.lane_shape.items():
            if not lane.startswith(":") and f.holds(shape):
                out.append(f'<path d="{f.path(shape)}" stroke="#d0d0d0" stroke-width="{lane_w:.1f}" '
                           'fill="none" stroke-linecap="round"/>')
    if len(route):
        out.append(f'<path d="{f.path(route)}" stroke="#9ecae1" stroke-width="{max(5 * f.s, 2):.1f}" '
                   'fill="none" stroke-linejoin="round"><title>the route</title></path>')
    for rec, log, out_kind in logs:
        out += _episode_svg(f, rec, log, out_kind, _key(rec) in base_keys, scoring)
    out.append("</svg>")
    return "".join(out)


def timeline(log: EpisodeLog, texts: Mapping[int, str], t_max: float) -> str:
    """Which instruction was active when, as a bar (one segment per instruction)."""
    width = 420.0
    if not log.t or t_max <= 0:
        return ""
    t0 = log.t[0]
    parts = [f'<svg class="tl" width="{width:.0f}" height="14" xmlns="http://www.w3.org/2000/svg">']
    ids = log.instruction
    start = 0
    for i in range(1, len(ids) + 1):
        if i == len(ids) or ids[i] != ids[start]:
            a, b = log.t[start] - t0, log.t[i - 1] - t0
            x, w = a / t_max * width, max((b - a) / t_max * width, 1.0)
            iid = ids[start]
            hue = (iid * 67) % 360
            fill = "#bbbbbb" if iid < 0 else f"hsl({hue},60%,55%)"
            text = "(no instruction yet)" if iid < 0 else texts.get(iid, f"instruction {iid}")
            parts.append(f'<rect x="{x:.1f}" y="1" width="{w:.1f}" height="12" fill="{fill}">'
                         f'<title>{esc(f"{a:.1f}–{b:.1f} s: {text}")}</title></rect>')
            start = i
    parts.append("</svg>")
    return "".join(parts)


def clip(render: Render, base: EpisodeLog, var: EpisodeLog, t_div: float) -> str:
    """Baseline and variant map views (the ego at its logged pose; other traffic is not in the
    log) from :data:`CLIP_BEFORE_S` before to :data:`CLIP_AFTER_S` after the divergence."""
    frames = []
    t = t_div - CLIP_BEFORE_S
    while t <= t_div + CLIP_AFTER_S + 1e-9:
        pair = []
        for log in (base, var):
            i = min(int(np.searchsorted(log.t, t)), len(log.t) - 1)
            png = render(log.x[i], log.y[i], log.yaw[i])
            pair.append(base64.b64encode(png).decode("ascii"))
        frames.append((t, pair))
        t += CLIP_STEP_S
    data = json.dumps([[round(ft, 1), p[0], p[1]] for ft, p in frames])
    first = frames[0][1]
    return (f'<div class="clip" data-frames="{esc(data)}"><figure><img alt="baseline" '
            f'src="data:image/png;base64,{first[0]}"><figcaption>baseline</figcaption></figure><figure>'
            f'<img alt="variant" src="data:image/png;base64,{first[1]}"><figcaption>variant</figcaption>'
            f'</figure><span class="clip-t"></span></div>')


def _episode_row(r: EpisodeRecord, kind: str, log: EpisodeLog | None, iset: InstructionSet | None,
                 t_max: float, scoring: Scoring) -> str:
    """One episode's table row: scores, how it ended, its infractions (when and where: the events
    ``scoring`` penalises), its timeline."""
    texts = {i.id: i.rendered() for i in iset.instructions} if iset is not None else {}
    if r.status != "done":
        ended = f"crashed: {r.message[:160]}"
    elif log is not None:
        ended = f"{r.termination} at t = {log.t[-1]:.1f} s, {log.progress[-1]:.0f} m"
    else:
        ended = str(r.termination)
    inf = "; ".join(f"{k} ×{f:g}" for k, f in r.infractions) or "—"
    if log is not None:  # when and where: the penalised events of the log
        at = [f"{ev.kind} at t = {ev.t:.1f} s, {ev.pos:.0f} m" for ev in scoring.penalised_events(log)]
        if at:
            inf += " (" + "; ".join(at) + ")"
    return (f'<tr data-agent="{esc(r.agent)}" data-family="{esc(r.family)}" data-outcome="{kind}">'
            f'<td class=l>{esc(r.agent)}</td><td class=l>{esc(r.family)}</td><td>{r.k}</td>'
            f'<td>{(r.ds or 0):.1f}</td><td>{(r.rc or 0):.1f}</td><td>{(r.is_ or 0):.3f}</td>'
            f'<td class=l>{esc(ended)}</td><td class=l>{esc(inf)}</td><td class=l>'
            f'{timeline(log, texts, t_max) if log is not None else ""}</td></tr>')


def _clips(draw: Render, with_kind: list[tuple[EpisodeRecord, EpisodeLog, str]],
           base_logs: Mapping[str, EpisodeLog]) -> list[str]:
    """The divergence clip of the first flip of each agent on the route."""
    clips = []
    seen: set[str] = set()
    for r, log, kind in with_kind:
        if kind != "flipped" or r.agent in seen or r.agent not in base_logs:
            continue
        t_div = divergence_t(base_logs[r.agent], log)
        if t_div is None:
            continue
        seen.add(r.agent)
        clips.append(f'<div data-agent="{esc(r.agent)}" data-family="{esc(r.family)}" '
                     'data-outcome="flipped">'
                     f'<p>{esc(r.agent)}, {esc(r.family)} k={r.k}: diverges from the baseline at t = '
                     f'{t_div:.1f} s (map view; other traffic is not in the log: '
                     '<code>icrsumo show</code> '
                     f'replays the full BEV)</p>{clip(draw, base_logs[r.agent], log, t_div)}</div>')
    return clips


def route_section(route: str, records: Sequence[EpisodeRecord], flipped: set[Key],
                  logs: Callable[[EpisodeRecord], EpisodeLog | None],
                  sets: Mapping[tuple[str, int], InstructionSet], net, draw: Render | None,
                  scoring: Scoring | None = None) -> str:
    """The section of ``route``: its episodes ``records`` (``flipped``: the keys of the flips),
    ``logs(record)`` their stored logs, ``sets`` the route's instruction sequences by (family,
    k), ``net`` its RoadNet (None: no map), ``draw`` its map views (None: no clips); the
    infractions marked are those the run's ``scoring`` penalises (None: the default scoring)."""
    scoring = scoring or get_scoring()
    recs = sorted(records, key=lambda r: (r.agent, r.family != Family.BASELINE, str(r.family), r.k))
    loaded = [(r, log) for r in recs if r.status == "done" and (log := logs(r)) is not None]
    log_of = {id(r): log for r, log in loaded}
    base_logs = {r.agent: log for r, log in loaded if r.family == Family.BASELINE}
    base_keys = {_key(r) for r, _ in loaded if r.family == Family.BASELINE}
    with_kind = [(r, log, outcome(r, _key(r) in flipped)) for r, log in loaded]
    svg = map_svg(net, with_kind, base_keys, scoring) if with_kind else "<p>no stored log to draw</p>"
    t_max = max((log.t[-1] - log.t[0] for _, log in loaded if log.t), default=0.0)
    rows = [_episode_row(r, outcome(r, _key(r) in flipped), log_of.get(id(r)), sets.get((str(r.family), r.k)),
                         t_max, scoring) for r in recs]
    clips = _clips(draw, with_kind, base_logs) if draw is not None else []
    return (f'<section class="route" id="route-{esc(route)}" data-route="{esc(route)}">'
            f'<h3>route {esc(route)}</h3>'
            f'{svg}<table><tr><th class=l>agent</th><th class=l>family</th><th>k</th><th>DS</th><th>RC</th>'
            f'<th>IS</th><th class=l>ended</th><th class=l>infractions</th><th class=l>instruction timeline '
            f'(hover: the text)</th></tr>{"".join(rows)}</table>{"".join(clips)}</section>')
