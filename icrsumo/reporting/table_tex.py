"""results.tex: the results table (:mod:`icrsumo.reporting.rows`) in LaTeX with booktabs, a rule
between agents, the notes (the conditioning gain, crashes) as comments."""

from __future__ import annotations

from icrsumo.results.summary import Summary

from .cells import tex_escape, tex_num
from .rows import ASKS_HEADER, notes, table_cells

_HEAD = ("Agent", "Family", "DS", "RC", "IS", r"$\Delta$DS [95\% CI]", r"$\Delta$RC [95\% CI]",
         r"$\Delta$IS", r"worst $\Delta$DS", r"RD \%", r"TO \%", "n", "crashed")


def results_tex(summary: Summary) -> str:
    """The LaTeX tabular (names escaped, :func:`icrsumo.reporting.cells.tex_escape`)."""
    _, text_rows = table_cells(summary)
    head = [*_HEAD, *([r"invalid \%"] if summary.has_answers else []),
            *([tex_escape(h) for h in ASKS_HEADER] if summary.has_asks else [])]
    tex = [r"\begin{tabular}{ll" + "r" * (len(head) - 2) + "}", r"\toprule",
           " & ".join(head) + r" \\", r"\midrule"]
    prev = None
    for agent, fam, text in text_rows:
        if prev is not None and agent != prev:
            tex.append(r"\midrule")
        cells = [tex_escape(agent) if agent != prev else "", tex_escape(fam)]
        cells += [tex_num(c) for c in text]
        tex.append(" & ".join(cells) + r" \\")
        prev = agent
    tex += [r"\bottomrule", r"\end{tabular}"]
    tex += ["% " + note for note in notes(summary)]
    return "\n".join(tex) + "\n"
