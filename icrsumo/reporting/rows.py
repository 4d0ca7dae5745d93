"""The results table (the ICR-Drive Table 1 layout) as text cells: one row per (agent, family),
the baseline row first per agent; DS, RC and the deltas with 1 decimal, IS with 3, RD / TO in %
of the family's episodes; per agent a "conditioning gain" row after its families when the run
has the ``blank`` family; the :data:`ASKS_HEADER` columns when an agent of the run asked for
clarification. results.md, results.tex and report.html show these cells."""

from __future__ import annotations

from icrsumo.results.summary import AskCounts, Block, ConditioningGain, FamilyStats, Interval, Summary

from .cells import ci, num, pct

HEADER = ("Agent", "Family", "DS", "RC", "IS", "ΔDS [95% CI]", "ΔRC [95% CI]", "ΔIS", "worst ΔDS",
          "RD %", "TO %", "n", "crashed")
#: the column an evaluation with a language-model agent adds (icrsumo.agents.llm)
ANSWERS_HEADER = "invalid %"
#: the columns a run in which an agent asked for clarification adds (icrsumo.sim.asking)
ASKS_HEADER = ("ask %", "asks/ep", "answered %")
#: the family cell of an agent's conditioning-gain row (a run with the blank family)
GAIN_ROW = "conditioning gain"

#: one row: agent, family, its cells after those two
TextRow = tuple[str, str, list[str]]


def _delta(x: float | None, interval: Interval | None, none: str) -> str:
    """A paired difference with its 95 % interval: ``-12.3 [-20.1, -4.0]``."""
    return f"{num(x, 1, True, none)} {ci(interval, '')}".strip()


def _cells(b: Block, none: str) -> list[str]:
    cells = [num(b.ds, 1, none=none), num(b.rc, 1, none=none), num(b.is_, 3, none=none)]
    if isinstance(b, FamilyStats):
        cells += [
            _delta(b.d_ds, b.d_ds_ci95, none),
            _delta(b.d_rc, b.d_rc_ci95, none),
            num(b.d_is, 3, True, none),
            num(b.worst_d_ds, 1, True, none),
        ]
    else:
        cells += [none] * 4
    return cells + [pct(b.rd, none), pct(b.to, none), str(b.n), str(b.n_crashed)]


def _gain_cells(g: ConditioningGain, none: str) -> list[str]:
    """An agent's conditioning-gain row: the gain (baseline − blank) in the Δ columns, n its pairs."""
    gain = [_delta(g.ds, g.ds_ci95, none), _delta(g.rc, g.rc_ci95, none), num(g.is_, 3, True, none)]
    return [none] * 3 + gain + [none] * 3 + [str(g.n), none]


def _answer_cell(b: Block | None, none: str) -> str:
    return pct(b.answers.invalid_rate if b and b.answers else None, none)


def _ask_cells(a: AskCounts | None, none: str) -> list[str]:
    """The :data:`ASKS_HEADER` cells: ask rate and answered share in %, asks per episode."""
    if a is None:
        return [none] * len(ASKS_HEADER)
    return [pct(a.ask_rate, none), num(a.asks_per_episode, 2, none=none), pct(a.answered_rate, none)]


def table_cells(summary: Summary) -> tuple[tuple[str, ...], list[TextRow]]:
    """The results table as text cells: its header and one (agent, family, cells) per row, as
    the markdown table shows them: per agent the baseline, its families and, with the blank
    family, its :data:`GAIN_ROW`."""
    answers, asks = summary.has_answers, summary.has_asks

    def extra(b: Block | None) -> list[str]:  # the optional columns (None: the gain row's)
        ask_cells = _ask_cells(b.asking if b else None, "—") if asks else []
        return ([_answer_cell(b, "—")] if answers else []) + ask_cells

    rows: list[TextRow] = []
    for agent, a in summary.agents.items():
        rows += [(agent, fam, _cells(b, "—") + extra(b)) for fam, b in a.blocks()]
        if a.conditioning_gain is not None:
            rows.append((agent, GAIN_ROW, _gain_cells(a.conditioning_gain, "—") + extra(None)))
    header = (*HEADER, *((ANSWERS_HEADER,) if answers else ()), *(ASKS_HEADER if asks else ()))
    return header, rows


def gain_note(summary: Summary) -> str:
    """The line under a table that says what its conditioning-gain rows hold ("" without them)."""
    if not summary.has_conditioning_gain:
        return ""
    return ("conditioning gain: what the instruction is worth against none, baseline DS minus blank DS "
            "paired on route and seed (RC and IS likewise); its Δ cells hold the gain (DS and RC with "
            "their 95% bootstrap CI), n its pairs. Positive: the agent drives better with the instruction.")


def ask_note(summary: Summary) -> str:
    """The line under a table that says what its ask columns hold ("" without them)."""
    if not summary.has_asks:
        return ""
    return ("ask %: the share of the row's episodes (n) in which the agent asked for clarification at "
            "least once; asks/ep: its asks per episode; answered %: the share of its asks the navigator "
            "answered (at most once per maneuver).")


def notes(summary: Summary) -> list[str]:
    """The lines under a table: :func:`gain_note`, :func:`ask_note` and :func:`crash_note`, each
    only when it has something to say."""
    return [n for n in (gain_note(summary), ask_note(summary), crash_note(summary)) if n]


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
