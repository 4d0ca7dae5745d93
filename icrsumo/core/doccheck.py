"""Typed reads of parsed JSON documents: scenario manifests (:mod:`icrsumo.world.scenario`),
instruction files (:mod:`icrsumo.instructions.store`) and episode logs (:mod:`icrsumo.results.logs`).
Each problem is one :class:`~icrsumo.core.errors.InputError` naming the file and the key path
(``ego.start.pos``, ``sets[2].instructions[0].intent``)."""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Any, TypeVar

from .errors import InputError, is_kind, short, type_problem

E = TypeVar("E", bound=StrEnum)


class DocChecker:
    """Typed reads of a parsed JSON document ``file``; each problem is an InputError naming the
    file and the key path, with ``fix``. The checks are these; a subclass may word its messages
    otherwise (:meth:`wrong_type`, :meth:`bad_number`, :meth:`missing`, :attr:`choice_fix`)."""

    #: strings longer than this are refused unless a read names its own limit (None: no limit)
    max_string: int | None = 10_000
    #: the fix of an unknown choice, given the allowed values
    choice_fix = "use one of {}"

    def __init__(self, file: object, fix: str) -> None:
        self.file, self.fix = file, fix

    def fail(self, place: str, problem: str, fix: str | None = None) -> InputError:
        return InputError(self.file, place, problem, self.fix if fix is None else fix)

    @staticmethod
    def _name(place: str) -> str:
        return place.rsplit(".", 1)[-1] or "value"

    # ------------------------------------------------------------------ wording
    def wrong_type(self, v: Any, place: str, kind: type) -> InputError:
        """``v`` at ``place`` is not a ``kind``: ``NAME must be KIND, not TYPE``."""
        return self.fail(place, type_problem(v, kind, self._name(place)))

    def bad_number(self, v: Any, place: str) -> InputError:
        """``v`` at ``place`` is not a finite number."""
        if not is_kind(v, (int, float)):
            return self.wrong_type(v, place, float)
        return self.fail(place, f"{self._name(place)} must be a finite number, not {short(v)}")

    def missing(self, key: str, prefix: str) -> InputError:
        """The object at ``prefix`` lacks ``key``: the error names the object."""
        return self.fail(prefix or "top level", f"missing key {key!r}")

    # ------------------------------------------------------------------ reads
    def key(self, d: dict, key: str, prefix: str = "") -> Any:
        """``d[key]`` (``prefix`` is the place of ``d``); a missing key is an error."""
        if key not in d:
            raise self.missing(key, prefix)
        return d[key]

    def typed(self, v: Any, kind: type, place: str) -> Any:
        """``v`` when it is a ``kind`` (a bool is neither an integer nor a number)."""
        if not is_kind(v, kind):
            raise self.wrong_type(v, place, kind)
        return v

    def obj(self, v: Any, place: str) -> dict:
        return self.typed(v, dict, place)

    def lst(self, v: Any, place: str, min_len: int = 0) -> list:
        self.typed(v, list, place)
        if len(v) < min_len:
            raise self.fail(place, f"has {len(v)} entries, needs at least {min_len}")
        return v

    def string(self, v: Any, place: str, nonempty: bool = False, limit: int | None = None) -> str:
        """A string (``nonempty``: not blank) of at most ``limit`` characters (default
        :attr:`max_string`)."""
        self.typed(v, str, place)
        if nonempty and not v.strip():
            raise self.fail(place, f"{self._name(place)} must not be empty")
        limit = self.max_string if limit is None else limit
        if limit is not None and len(v) > limit:
            raise self.fail(place, f"{self._name(place)} is {len(v)} characters long (at most {limit})")
        return v

    def boolean(self, v: Any, place: str) -> bool:
        return self.typed(v, bool, place)

    def integer(self, v: Any, place: str, lo: int | None = None, hi: int | None = None) -> int:
        self.typed(v, int, place)
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            rng = f"{lo if lo is not None else '-inf'} .. {hi if hi is not None else 'inf'}"
            raise self.fail(place, f"{self._name(place)} = {short(v)} is out of range ({rng})")
        return v

    def number(self, v: Any, place: str, lo: float | None = None, hi: float | None = None,
               lo_open: bool = False) -> float:
        """A finite JSON number (an integer is fine) within [lo, hi] (``lo_open``: > lo)."""
        try:
            f = float(v) if is_kind(v, (int, float)) else math.nan
        except OverflowError:
            f = math.inf
        if not math.isfinite(f):
            raise self.bad_number(v, place)
        below = lo is not None and (f <= lo if lo_open else f < lo)
        if below or (hi is not None and f > hi):
            left = "(" if lo_open else "["
            raise self.fail(place, f"{self._name(place)} = {short(v)} is out of range "
                            f"({left}{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}])")
        return f

    def choice(self, v: Any, place: str, values, what: str) -> str:
        """``v`` as one of the strings ``values`` (an enum class or a sequence)."""
        text = self.typed(v, str, place)
        allowed = [str(x) for x in values]
        if text not in allowed:
            raise self.fail(place, f"unknown {what} {short(text)}",
                            self.choice_fix.format(", ".join(allowed)))
        return text

    def member(self, v: Any, place: str, enum: type[E], what: str) -> E:
        """``v`` as a member of the string enum ``enum``."""
        return enum(self.choice(v, place, enum, what))

