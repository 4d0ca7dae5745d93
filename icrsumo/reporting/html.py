"""``OUT/report.html``: one self-contained page (no network, no external file) to browse an
evaluation: the tables, the flips with the decision and instruction at fault, and per route a
paired view (:mod:`icrsumo.reporting.html_route`). Filters by agent, family and outcome. Every
text from a file (instructions, route ids, agent names) is HTML-escaped."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from icrsumo.core.fsio import write_atomic
from icrsumo.core.types import EpisodeLog, EpisodeRecord, InstructionSet
from icrsumo.results.summary import Summary
from icrsumo.scoring import get_scoring

from .html_route import Render, esc, route_section
from .rows import ask_note, gain_note, table_cells

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


def _head(summary: Summary) -> str:
    ep = summary.episodes
    return (f"<h1>icrsumo report: {esc(summary.suite)}</h1><p>seed {summary.seed}, K = {summary.k}, "
            f"scoring {esc(summary.scoring or '')}; {ep.done} episodes done, {ep.crashed} "
            "crashed.</p>")


def _filters(agents: list[str], families: list[str]) -> str:
    opts = "".join(f'<option value="{esc(a)}">{esc(a)}</option>' for a in agents)
    fopts = "".join(f'<option value="{esc(f)}">{esc(f)}</option>' for f in families if f != "baseline")
    return (f'<div class="filters">agent <select id="f-agent"><option value="">all</option>{opts}'
            '</select> '
            f'family <select id="f-family"><option value="">all</option>{fopts}</select> outcome '
            '<select id="f-outcome"><option value="">all</option><option value="flipped">flipped (failed '
            'where the baseline completed)</option><option value="failed">failed</option><option '
            'value="completed">completed</option><option value="crashed">crashed</option></select> '
            '— routes shown: <span id="shown"></span></div>')


def _results(summary: Summary) -> str:
    header, rows = table_cells(summary)
    table = ["<h2>Results</h2><table><tr>" + "".join(f"<th>{esc(h)}</th>" for h in header) + "</tr>"]
    for agent, fam, cells in rows:
        table.append(f'<tr data-agent="{esc(agent)}" data-family="{esc(fam)}"><td class="l">{esc(agent)}</td>'
                     f'<td class="l">{esc(fam)}</td>' + "".join(f"<td>{esc(c)}</td>" for c in cells)
                     + "</tr>")
    table.append("</table>")
    return "".join(table) + "".join(f"<p>{esc(n)}</p>" for n in (gain_note(summary), ask_note(summary)) if n)


def _flip_row(f: Mapping) -> str:
    d, ins = f.get("decision") or {}, f.get("instruction") or {}
    return (f'<tr data-agent="{esc(f["agent"])}" data-family="{esc(f["family"])}" data-outcome="flipped">'
            f'<td class=l>{esc(f["agent"])}</td><td class=l><a href="#route-{esc(f["route_id"])}">'
            f'{esc(f["route_id"])}</a></td><td class=l>{esc(f["family"])}</td><td>{f["k"]}</td>'
            f'<td class=l>{esc(f["termination"])}</td><td class=l>'
            f'{esc(d["kind"]) + " at " + format(d["pos"], ".0f") + " m" if d else "—"}</td>'
            f'<td class=l>{esc(d.get("route_intent", ""))}</td>'
            f'<td class=l>{esc(d.get("executed") or d.get("outcome", ""))}</td>'
            f'<td class=l>{esc(ins.get("text", ""))}</td>'
            f'<td class=l>{esc(ins.get("template", ""))}</td></tr>')


def _flips(attribution: Mapping) -> str:
    head = ("<h2>Flips: the decision and the instruction at fault</h2><table><tr><th class=l>agent</th>"
            "<th class=l>route</th><th class=l>family</th><th>k</th><th class=l>ended</th>"
            "<th class=l>decision</th><th class=l>route wanted</th><th class=l>driven</th>"
            "<th class=l>instruction active there</th>"
            "<th class=l>template</th></tr>")
    return head + "".join(_flip_row(f) for f in attribution.get("flips", [])) + "</table>"


def html_report(summary: Summary, records: Sequence[EpisodeRecord], attribution: Mapping,
                logs: Callable[[EpisodeRecord], EpisodeLog | None],
                sets: Callable[[str], Mapping[tuple[str, int], InstructionSet]],
                nets: Callable[[str], object | None],
                render: Callable[[str], Render | None]) -> str:
    """The page's HTML. ``attribution``: the attribution document
    (:func:`icrsumo.results.attribution.attribution_doc`); ``logs(record)``: its stored log;
    ``sets(route)``: the route's instruction sequences by (family, k); ``nets(route)``: its
    RoadNet (None: no map); ``render(route)``: a function (x, y, yaw) -> PNG bytes of the map
    view there (None: no clips)."""
    agents = sorted({r.agent for r in records})
    families = [f for f in ("baseline", *summary.families) if any(r.family == f for r in records)]
    flipped = {(f["agent"], f["route_id"], f["family"], f["k"], f["seed"])
               for f in attribution.get("flips", [])}
    by_route: dict[str, list[EpisodeRecord]] = {}
    for r in records:
        by_route.setdefault(r.route_id, []).append(r)
    sections, scoring = [], get_scoring(summary.scoring)
    for route in sorted(by_route):
        route_sets = sets(route)
        sections.append(route_section(route, by_route[route], flipped, logs, route_sets, nets(route),
                                      render(route), scoring))
    return ("<!DOCTYPE html><html lang=en><head><meta charset=utf-8><title>icrsumo report</title>"
            f"<style>{_CSS}</style></head><body>{_head(summary)}{_filters(agents, families)}"
            f"{_results(summary)}{_flips(attribution)}"
            f"<h2>Routes ({len(by_route)})</h2>{''.join(sections)}<script>{_JS}</script></body></html>\n")


def write_html_report(path: Path, *args, **kwargs) -> None:
    """Write :func:`html_report`'s page to ``path`` atomically."""
    write_atomic(Path(path), html_report(*args, **kwargs))
