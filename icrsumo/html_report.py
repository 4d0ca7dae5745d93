"""``OUT/report.html``: one self-contained page (no network, no external file) to browse an
evaluation: the tables, the flips with the decision and instruction at fault, and per route a
paired view: the baseline and every variant over the map, an instruction timeline per episode,
where, when and why each episode ended with its infractions, and a map view of the divergence.
Filters by agent, family and outcome. Every text from a file (instructions, route ids, agent
names) is HTML-escaped."""

from __future__ import annotations

import base64
import html
import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from .fsio import write_atomic
from .scoring.penalties import PENALTIES
from .types import EpisodeLog, EpisodeRecord, InstructionSet
from .vocab import Family

#: m: a drawn trajectory keeps the points that are more than this off its simplified line
SIMPLIFY_M = 0.3
#: at most this many points of a trajectory are drawn (evenly spaced along it)
MAX_POINTS = 300
#: the divergence clip: seconds before and after the divergence, seconds between frames
CLIP_BEFORE_S, CLIP_AFTER_S, CLIP_STEP_S = 1.0, 6.0, 1.0
#: m: a variant has diverged where its ego is this far from the baseline's at the same time
DIVERGED_M = 3.0
_COLOURS = {"done": "#1a9850", "RD": "#d73027", "TO": "#fc8d59", "crashed": "#7b3294"}

Key = tuple[str, str, str, int, int]


def _e(x: object) -> str:
    return html.escape(str(x), quote=True)


def outcome(r: EpisodeRecord, flipped: bool) -> str:
    """The filter's outcome of an episode: crashed, flipped (failed where its baseline
    completed), failed, or completed."""
    if r.status != "done":
        return "crashed"
    if r.termination_class == "done":
        return "completed"
    return "flipped" if flipped else "failed"


def divergence_t(base: EpisodeLog, var: EpisodeLog) -> float | None:
    """The first time (s) the variant's ego is :data:`DIVERGED_M` or more from the baseline's
    at the same simulation time (None: never within the shorter log)."""
    n = min(len(base.t), len(var.t))
    if n == 0:
        return None
    bx, by = np.asarray(base.x[:n]), np.asarray(base.y[:n])
    d = np.hypot(bx - np.asarray(var.x[:n]), by - np.asarray(var.y[:n]))
    idx = np.flatnonzero(d >= DIVERGED_M)
    return float(var.t[idx[0]]) if len(idx) else None


def simplify(xy: np.ndarray, tol: float = SIMPLIFY_M) -> np.ndarray:
    """(M, 2) m: the polyline ``xy`` with the points that lie within ``tol`` m of the line
    between their kept neighbours dropped (Ramer-Douglas-Peucker; the ends are kept)."""
    n = len(xy)
    if n < 3:
        return xy
    keep = np.zeros(n, dtype=bool)
    keep[[0, n - 1]] = True
    stack = [(0, n - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        seg = xy[b] - xy[a]
        rel = xy[a + 1:b] - xy[a]
        length = float(np.hypot(*seg))
        if length > 0:
            dist = np.abs(seg[0] * rel[:, 1] - seg[1] * rel[:, 0]) / length
        else:
            dist = np.hypot(rel[:, 0], rel[:, 1])
        i = int(np.argmax(dist))
        if dist[i] > tol:
            keep[a + 1 + i] = True
            stack += [(a, a + 1 + i), (a + 1 + i, b)]
    return xy[keep]


def _points(log: EpisodeLog) -> np.ndarray:
    """(M, 2) m: the trajectory, simplified to :data:`SIMPLIFY_M` (at most :data:`MAX_POINTS`
    points, the last one kept)."""
    xy = simplify(np.column_stack([log.x, log.y])) if log.t else np.zeros((0, 2))
    if len(xy) > MAX_POINTS:
        idx = np.unique(np.append(np.linspace(0, len(xy) - 1, MAX_POINTS).round().astype(int), len(xy) - 1))
        xy = xy[idx]
    return xy


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


def _map_svg(net, logs: Sequence[tuple[EpisodeRecord, EpisodeLog, str]], base_keys: set[Key]) -> str:
    """The route, the lanes around it and every episode's trajectory with its end and
    infractions, as an inline SVG."""
    first = logs[0][1]
    route = np.asarray([p[:2] for p in first.route], dtype=float) if first.route else np.zeros((0, 2))
    every = [route] + [_points(log) for _, log, _ in logs]
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
        key = (rec.agent, rec.route_id, str(rec.family), rec.k, rec.seed)
        base = key in base_keys
        colour = "#000000" if base else _COLOURS.get(str(rec.termination_class) or "crashed", "#777777")
        attrs = (f'class="ep" data-agent="{_e(rec.agent)}" data-family="{_e(rec.family)}" '
                 f'data-outcome="{out_kind}"')
        label = f"{rec.agent} {rec.family} k={rec.k}: {rec.termination}, DS {rec.ds:.1f}"
        pts = _points(log)
        out.append(f'<g {attrs}><path d="{f.path(pts)}" stroke="{colour}" '
                   f'stroke-width="{2.5 if base else 1.5}" fill="none" opacity="{1.0 if base else 0.75}">'
                   f'<title>{_e(label)}</title></path>')
        if len(pts):
            ex, ey = f.at(*pts[-1])
            out.append(f'<circle cx="{ex:.1f}" cy="{ey:.1f}" r="4" fill="{colour}"><title>{_e(label)} '
                       f'— ended at t = {log.t[-1]:.1f} s, {log.progress[-1]:.0f} m along the route'
                       '</title></circle>')
        for ev in log.events:
            if ev.x or ev.y:
                cx, cy = f.at(ev.x, ev.y)
                out.append(f'<text x="{cx:.1f}" y="{cy:.1f}" font-size="12" fill="{colour}" '
                           f'text-anchor="middle">✕<title>{_e(ev.kind)} at t = {ev.t:.1f} s, {ev.pos:.0f} m'
                           f'{(" with " + _e(ev.other)) if ev.other else ""}</title></text>')
        out.append("</g>")
    out.append("</svg>")
    return "".join(out)


def _timeline(rec: EpisodeRecord, log: EpisodeLog, texts: Mapping[int, str], t_max: float) -> str:
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
                         f'<title>{_e(f"{a:.1f}–{b:.1f} s: {text}")}</title></rect>')
            start = i
    parts.append("</svg>")
    return "".join(parts)


def _clip(render: Callable[[float, float, float], bytes], base: EpisodeLog, var: EpisodeLog,
          t_div: float) -> str:
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
    return (f'<div class="clip" data-frames="{_e(data)}"><figure><img alt="baseline" '
            f'src="data:image/png;base64,{first[0]}"><figcaption>baseline</figcaption></figure><figure>'
            f'<img alt="variant" src="data:image/png;base64,{first[1]}"><figcaption>variant</figcaption>'
            f'</figure><span class="clip-t"></span></div>')


_CSS = """
body{font-family:system-ui,sans-serif;margin:1.5em;color:#222;max-width:1400px}
table{border-collapse:collapse;font-size:13px;margin:.5em 0}
td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}td.l,th.l{text-align:left}
section.route{border-top:2px solid #888;margin-top:1.5em}
.filters{position:sticky;top:0;background:#fff;padding:.4em 0;border-bottom:1px solid #ccc;z-index:1}
.clip{display:flex;gap:8px;align-items:center}.clip img{width:160px;image-rendering:pixelated}
figure{margin:0;text-align:center;font-size:12px}.hidden{display:none}
svg.map{max-width:100%;height:auto;border:1px solid #ccc}
"""

_JS = """
(function(){
  function apply(){
    var a=document.getElementById('f-agent').value,f=document.getElementById('f-family').value,
        o=document.getElementById('f-outcome').value;
    document.querySelectorAll('[data-agent]').forEach(function(el){
      var ok=(a===''||el.dataset.agent===a)&&(f===''||el.dataset.family===f||el.dataset.family==='baseline')
        &&(o===''||!el.dataset.outcome||el.dataset.outcome===o||el.dataset.family==='baseline');
      el.classList.toggle('hidden',!ok);
    });
    var shown=0;
    document.querySelectorAll('section.route').forEach(function(s){
      var any=Array.prototype.some.call(s.querySelectorAll('tr[data-agent]'),function(r){
        return !r.classList.contains('hidden')&&(r.dataset.family!=='baseline'||(o===''&&f==='')
          ||(o!==''&&r.dataset.outcome===o));});
      s.classList.toggle('hidden',!any); if(any){shown++;}
    });
    document.getElementById('shown').textContent=shown;
  }
  ['f-agent','f-family','f-outcome'].forEach(function(id){
    document.getElementById(id).addEventListener('change',apply);});
  apply();
  document.querySelectorAll('.clip').forEach(function(c){
    var frames=JSON.parse(c.dataset.frames),imgs=c.querySelectorAll('img'),lab=c.querySelector('.clip-t'),i=0;
    setInterval(function(){i=(i+1)%frames.length;imgs[0].src='data:image/png;base64,'+frames[i][1];
      imgs[1].src='data:image/png;base64,'+frames[i][2];lab.textContent='t = '+frames[i][0]+' s';},500);
  });
})();
"""


def html_report(summary: dict, records: Sequence[EpisodeRecord], attribution: Mapping,
                logs: Callable[[EpisodeRecord], EpisodeLog | None],
                sets: Callable[[str], Mapping[tuple[str, int], InstructionSet]],
                nets: Callable[[str], object | None],
                render: Callable[[str], Callable[[float, float, float], bytes] | None]) -> str:
    """The page's HTML. ``logs(record)``: its stored log; ``sets(route)``: the route's
    instruction sequences by (family, k); ``nets(route)``: its RoadNet (None: no map);
    ``render(route)``: a function (x, y, yaw) -> PNG bytes of the map view there (None: no
    clips)."""
    from .report import table_cells

    agents = sorted({r.agent for r in records})
    families = [f for f in ("baseline", *summary.get("families", [])) if any(r.family == f for r in records)]
    flipped = {(f["agent"], f["route_id"], f["family"], f["k"], f["seed"])
               for f in attribution.get("flips", [])}
    ep = summary["episodes"]
    head = (f"<h1>icrsumo report: {_e(summary['suite'])}</h1><p>seed {summary['seed']}, K = {summary['k']}, "
            f"scoring {_e(summary.get('scoring', ''))}; {ep['done']} episodes done, {ep['crashed']} "
            "crashed.</p>")
    opts = "".join(f'<option value="{_e(a)}">{_e(a)}</option>' for a in agents)
    fopts = "".join(f'<option value="{_e(f)}">{_e(f)}</option>' for f in families if f != "baseline")
    filters = (f'<div class="filters">agent <select id="f-agent"><option value="">all</option>{opts}'
               '</select> '
               f'family <select id="f-family"><option value="">all</option>{fopts}</select> outcome '
               '<select id="f-outcome"><option value="">all</option><option value="flipped">flipped (failed '
               'where the baseline completed)</option><option value="failed">failed</option><option '
               'value="completed">completed</option><option value="crashed">crashed</option></select> '
               '— routes shown: <span id="shown"></span></div>')
    header, rows = table_cells(summary)
    table = ["<h2>Results</h2><table><tr>" + "".join(f"<th>{_e(h)}</th>" for h in header) + "</tr>"]
    for agent, fam, cells in rows:
        table.append(f'<tr data-agent="{_e(agent)}" data-family="{_e(fam)}"><td class="l">{_e(agent)}</td>'
                     f'<td class="l">{_e(fam)}</td>' + "".join(f"<td>{_e(c)}</td>" for c in cells) + "</tr>")
    table.append("</table>")
    flips = ["<h2>Flips: the decision and the instruction at fault</h2><table><tr><th class=l>agent</th>"
             "<th class=l>route</th><th class=l>family</th><th>k</th><th class=l>ended</th>"
             "<th class=l>decision</th><th class=l>route wanted</th><th class=l>driven</th>"
             "<th class=l>instruction active there</th>"
             "<th class=l>template</th></tr>"]
    for f in attribution.get("flips", []):
        d, ins = f.get("decision") or {}, f.get("instruction") or {}
        flips.append(
            f'<tr data-agent="{_e(f["agent"])}" data-family="{_e(f["family"])}" data-outcome="flipped">'
            f'<td class=l>{_e(f["agent"])}</td><td class=l><a href="#route-{_e(f["route_id"])}">'
            f'{_e(f["route_id"])}</a></td><td class=l>{_e(f["family"])}</td><td>{f["k"]}</td>'
            f'<td class=l>{_e(f["termination"])}</td><td class=l>'
            f'{_e(d["kind"]) + " at " + format(d["pos"], ".0f") + " m" if d else "—"}</td>'
            f'<td class=l>{_e(d.get("route_intent", ""))}</td>'
            f'<td class=l>{_e(d.get("executed") or d.get("outcome", ""))}</td>'
            f'<td class=l>{_e(ins.get("text", ""))}</td><td class=l>{_e(ins.get("template", ""))}</td></tr>')
    flips.append("</table>")

    by_route: dict[str, list[EpisodeRecord]] = {}
    for r in records:
        by_route.setdefault(r.route_id, []).append(r)
    sections = []
    for route in sorted(by_route):
        recs = sorted(by_route[route],
                      key=lambda r: (r.agent, r.family != Family.BASELINE, str(r.family), r.k))
        route_sets = sets(route)
        loaded = [(r, logs(r)) for r in recs if r.status == "done"]
        loaded = [(r, log) for r, log in loaded if log is not None]
        log_of = {id(r): log for r, log in loaded}
        base_logs = {r.agent: log for r, log in loaded if r.family == Family.BASELINE}
        base_keys = {(r.agent, r.route_id, str(r.family), r.k, r.seed) for r, _ in loaded
                     if r.family == Family.BASELINE}
        with_kind = [(r, log, outcome(r, (r.agent, r.route_id, str(r.family), r.k, r.seed) in flipped))
                     for r, log in loaded]
        svg = _map_svg(nets(route), with_kind, base_keys) if with_kind else "<p>no stored log to draw</p>"
        t_max = max((log.t[-1] - log.t[0] for _, log in loaded if log.t), default=0.0)
        rows_html = []
        for r in recs:
            key = (r.agent, r.route_id, str(r.family), r.k, r.seed)
            kind = outcome(r, key in flipped)
            log = log_of.get(id(r))
            iset = route_sets.get((str(r.family), r.k))
            texts = {i.id: i.rendered() for i in iset.instructions} if iset is not None else {}
            if r.status != "done":
                ended = f"crashed: {r.message[:160]}"
            elif log is not None:
                ended = f"{r.termination} at t = {log.t[-1]:.1f} s, {log.progress[-1]:.0f} m"
            else:
                ended = str(r.termination)
            inf = "; ".join(f"{k} ×{f:g}" for k, f in r.infractions) or "—"
            if log is not None:  # when and where: the penalised events of the log
                at = [f"{ev.kind} at t = {ev.t:.1f} s, {ev.pos:.0f} m" for ev in log.events
                      if ev.kind in PENALTIES]
                if at:
                    inf += " (" + "; ".join(at) + ")"
            rows_html.append(
                f'<tr data-agent="{_e(r.agent)}" data-family="{_e(r.family)}" data-outcome="{kind}">'
                f'<td class=l>{_e(r.agent)}</td><td class=l>{_e(r.family)}</td><td>{r.k}</td>'
                f'<td>{(r.ds or 0):.1f}</td><td>{(r.rc or 0):.1f}</td><td>{(r.is_ or 0):.3f}</td>'
                f'<td class=l>{_e(ended)}</td><td class=l>{_e(inf)}</td><td class=l>'
                f'{_timeline(r, log, texts, t_max) if log is not None else ""}</td></tr>')
        clips = []
        draw = render(route)
        if draw is not None:
            seen: set[str] = set()
            for r, log, kind in with_kind:  # the first flip of each agent on this route
                if kind != "flipped" or r.agent in seen or r.agent not in base_logs:
                    continue
                t_div = divergence_t(base_logs[r.agent], log)
                if t_div is None:
                    continue
                seen.add(r.agent)
                clips.append(f'<div data-agent="{_e(r.agent)}" data-family="{_e(r.family)}" '
                             'data-outcome="flipped">'
                             f'<p>{_e(r.agent)}, {_e(r.family)} k={r.k}: diverges from the baseline at t = '
                             f'{t_div:.1f} s (map view; other traffic is not in the log: '
                             '<code>icrsumo show</code> '
                             f'replays the full BEV)</p>{_clip(draw, base_logs[r.agent], log, t_div)}</div>')
        sections.append(
            f'<section class="route" id="route-{_e(route)}" data-route="{_e(route)}">'
            f'<h3>route {_e(route)}</h3>'
            f'{svg}<table><tr><th class=l>agent</th><th class=l>family</th><th>k</th><th>DS</th><th>RC</th>'
            f'<th>IS</th><th class=l>ended</th><th class=l>infractions</th><th class=l>instruction timeline '
            f'(hover: the text)</th></tr>{"".join(rows_html)}</table>{"".join(clips)}</section>')
    return ("<!DOCTYPE html><html lang=en><head><meta charset=utf-8><title>icrsumo report</title>"
            f"<style>{_CSS}</style></head><body>{head}{filters}{''.join(table)}{''.join(flips)}"
            f"<h2>Routes ({len(by_route)})</h2>{''.join(sections)}<script>{_JS}</script></body></html>\n")


def write_html_report(path: Path, *args, **kwargs) -> None:
    """Write :func:`html_report`'s page to ``path`` atomically."""
    write_atomic(Path(path), html_report(*args, **kwargs))

