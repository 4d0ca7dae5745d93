"""The results table (the ICR-Drive Table 1 layout) as text cells: one row per (agent, family),
the baseline row first per agent; DS, RC and the deltas with 1 decimal, IS with 3, RD / TO in %
of the family's episodes. results.md, results.tex and report.html show these cells."""

from __future__ import annotations

from icrsumo.results.summary import Block, FamilyStats, Summary

from .cells import ci, num, pct

HEADER = ("Agent", "Family", "DS", "RC", "IS", "ΔDS [95% CI]", "ΔRC [95% CI]", "ΔIS", "worst ΔDS",
          "RD %", "TO %", "n", "crashed")
#: the column an evaluation with a language-model agent adds (icrsumo.agents.llm)
ANSWERS_HEADER = "invalid %"

#: one row: agent, family, its cells after those two
TextRow = tuple[str, str, list[str]]


def _cells(b: Block, none: str) -> list[str]:
    cells = [num(b.ds, 1, none=none), num(b.rc, 1, none=none), num(b.is_, 3, none=none)]
    if isinstance(b, FamilyStats):
        cells += [
            f"{num(b.d_ds, 1, True, none)} {ci(b.d_ds_ci95, '')}".strip(),
            f"{num(b.d_rc, 1, True, none)} {ci(b.d_rc_ci95, '')}".strip(),
            num(b.d_is, 3, True, none),
            num(b.worst_d_ds, 1, True, none),
        ]
    else:
        cells += [none] * 4
    return cells + [pct(b.rd, none), pct(b.to, none), str(b.n), str(b.n_crashed)]


def _answer_cell(b: Block, none: str) -> str:
    return pct(b.answers.invalid_rate if b.answers else None, none)


def table_cells(summary: Summary) -> tuple[tuple[str, ...], list[TextRow]]:
    """The results table as text cells: its header and one (agent, family, cells) per row, as
    the markdown table shows them."""
    if summary.has_answers:
        return (*HEADER, ANSWERS_HEADER), [(agent, fam, [*_cells(b, "—"), _answer_cell(b, "—")])
                                           for agent, fam, b in summary.rows()]
    return HEADER, [(agent, fam, _cells(b, "—")) for agent, fam, b in summary.rows()]


def crash_note(summary: Summary) -> str:
    """The line under a table that says what crashed episodes did to it ("" when none did)."""
    crashed = summary.episodes.crashed
    if not crashed:
        return ""
    unpaired = sum(f.unpaired for a in summary.agents.values() for f in a.families.values())
    also = (f"; {unpaired} finished variant episodes whose baseline crashed are left out too"
            if unpaired else "")
    return (f"{crashed} episode{'s' * (crashed != 1)} crashed and {'are' if crashed != 1 else 'is'} left "
            f"out: each family's row covers only its complete pairs (variant and baseline both finished; "
            f"n counts them){also}. `icrsumo evaluate --retry-crashed` runs the crashed ones again.")
