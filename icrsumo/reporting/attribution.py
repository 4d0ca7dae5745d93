"""The attribution's files (:mod:`icrsumo.results.attribution`): attribution.json, attribution.md (the
rows' decision statistics, the templates behind flips, every flip) and its figures."""

from __future__ import annotations

from pathlib import Path

from icrsumo.core.fsio import dumps_json, write_atomic
from icrsumo.results.summary import Summary

from .cells import file_name, md_cell, num
from .figures import confusion_heatmaps, figure_or_note, template_flip_bars

_OUTCOMES = ("followed_route", "followed_text", "other", "not_reached")


def _percent(x: float | None) -> float | None:
    return None if x is None else 100.0 * x


def _decision_rows(summary: Summary) -> list[str]:
    """Per agent and family (with decision statistics) the decisions' outcomes, compliance
    under a contradicting text and adherence to the route."""
    md = ["| Agent | Family | followed route | followed text | other | not reached | compliance % | "
          "adherence % |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for agent, fam, b in summary.rows():
        d = b.decisions
        if d is None:
            continue
        md.append("| " + " | ".join([md_cell(agent), fam, *(str(d.decisions[o]) for o in _OUTCOMES),
                                     num(_percent(d.compliance), 1), num(_percent(d.adherence), 1)]) + " |")
    return md


def _template_rows(doc: dict, top: int) -> list[str]:
    md = ["", f"Flips (a variant failed where its baseline completed): {len(doc['flips'])}. "
              f"Templates and noise operations active at the decision where the ego left the route "
              f"(top {top}):", "",
          "| Family | Template | flips | uses | flip rate % | example |", "|---|---|---:|---:|---:|---|"]
    for r in doc["templates"][:top]:
        md.append(f"| {r['family']} | {md_cell(r['template'])} | {r['flips']} | {r['uses']} | "
                  f"{num(_percent(r['flip_rate']), 1)} | {md_cell(r['example'])} |")
    return md


def _flip_rows(doc: dict) -> list[str]:
    md = ["", "Every flip: the decision where the ego left the route and the instruction active there.",
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
    return md


def attribution_table(summary: Summary, doc: dict, top: int = 20) -> str:
    """Markdown: per agent and family the decisions' outcomes, compliance under a contradicting
    text and adherence to the route; then the ``top`` templates by the flips they were active
    at (first-divergence attribution); then every flip."""
    return "\n".join(_decision_rows(summary) + _template_rows(doc, top) + _flip_rows(doc)) + "\n"


def write_attribution(summary: Summary, doc: dict, out_dir: Path) -> None:
    """Write attribution.json (flips and template ranking), attribution.md,
    figures/confusion_<agent>.png and figures/template_flips.png."""
    out = Path(out_dir)
    write_atomic(out / "attribution.json", dumps_json(doc))
    write_atomic(out / "attribution.md", attribution_table(summary, doc))
    for agent in summary.agents:
        path = out / "figures" / f"confusion_{file_name(agent)}.png"
        figure_or_note(confusion_heatmaps, summary, agent, path)
    figure_or_note(template_flip_bars, doc, out / "figures" / "template_flips.png")
