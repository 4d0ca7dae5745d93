"""Cells of the reports: text safe in a Markdown table, in LaTeX and in a CSV file (names and
texts come from users and servers), number formats, and file names made from names."""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterable, Sequence
from typing import Any

from icrsumo.core.errors import visible
from icrsumo.core.fsio import MAX_FILE_NAME, bounded_name

_TEX_SPECIAL = {"\\": r"\textbackslash{}", "~": r"\textasciitilde{}", "^": r"\^{}",
                **{c: "\\" + c for c in "&%$#_{}"}}
#: first characters that make a spreadsheet read a CSV cell as a formula
_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def md_cell(s: str) -> str:
    """``s`` safe in a Markdown table cell: one line, ``|`` escaped, control characters written
    out (:func:`icrsumo.core.errors.visible`). Every Markdown table of a name or a text uses it."""
    return visible(" ".join(str(s).split())).replace("|", "\\|")


def tex_escape(s: str) -> str:
    """``s`` safe in LaTeX: one line, control characters written out
    (:func:`icrsumo.core.errors.visible`), then LaTeX's special characters escaped."""
    return "".join(_TEX_SPECIAL.get(c, c) for c in visible(" ".join(str(s).split())))


def tex_num(cell: str) -> str:
    """Numeric cell text to LaTeX: "-" as a math minus, "—" (no data) as "--"."""
    return cell.replace("−", "-").replace("-", "$-$").replace("—", "--")


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


def csv_text(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    """A CSV file's text: ``header``, then ``rows`` (every cell through :func:`csv_cell`)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for row in rows:
        w.writerow([csv_cell(v) for v in row])
    return buf.getvalue()


def num(x: float | None, nd: int, sign: bool = False, none: str = "—") -> str:
    """``x`` with ``nd`` decimals (``sign``: a leading + or -, none on a zero); ``none`` for None."""
    if x is None:
        return none
    s = f"{x:+.{nd}f}" if sign else f"{x:.{nd}f}"
    return s.lstrip("+-") if float(s) == 0.0 else s


def pct(x: float | None, none: str) -> str:
    """A fraction in % with one decimal; ``none`` for None."""
    return none if x is None else f"{100.0 * x:.1f}"


def ci(interval: Sequence[float] | None, none: str) -> str:
    """A 95 % interval as ``[lo, hi]`` with one decimal; ``none`` for None."""
    return none if interval is None else f"[{interval[0]:.1f}, {interval[1]:.1f}]"


def p_text(x: float | None) -> str:
    """A p-value: three decimals, "< 0.001" below, "—" for None."""
    return "—" if x is None else ("< 0.001" if x < 0.001 else f"{x:.3f}")


def file_name(s: str) -> str:
    """The part of a file name that stands for ``s`` (an agent name, a family): letters,
    digits and ``_.-`` kept, the rest ``_``, at most half of
    :data:`icrsumo.core.fsio.MAX_FILE_NAME` characters (a longer name is cut and ends with a hash of it)."""
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", s)
    name = name if name not in ("", ".", "..") else f"x_{name}"
    return bounded_name(name, s, MAX_FILE_NAME // 2)
