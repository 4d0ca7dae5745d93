"""Compact, byte-stable JSON of episode logs and results.

A log is stored as::

    {"version": 1, "route_id": ..., "agent": ..., "family": ..., "k": ..., "seed": ...,
     "step_length": ..., "route_length": ..., "termination": ..., "termination_t": ...,
     "message": ..., "route": [[x, y], ...], "steps": {"t": [...], "x": [...], ...},
     "events": [[kind, t, pos, other, x, y], ...]}

Keys come in that fixed order, per-step values are columns, and floats are rounded (t and
termination_t to 1e-3 s, x/y/progress/route_dist/pos/route_length/route to 0.01 m, yaw to 1e-4 rad,
speed to 1e-3 m/s, step_length to 1e-6 s), so the same episode always gives the same bytes and
already-rounded logs round-trip exactly. Version 2 holds what the leaderboard's rules need to
rescore the episode (:mod:`icrsumo.scoring`): the route polyline,
the OutsideRouteLanesTest bits per step and a contact event per step of contact; version 1 logs
cannot be rescored and are refused. Optional keys after ``events``, present only when they have
entries: ``model_calls``, ``guard`` (one object ``{"t", "progress", "instruction_id", "verdict",
"reason"}`` per decision; a repair's adds ``"text"`` and ``"baseline_id"``:
:class:`~icrsumo.core.types.GuardDecision`) and ``asks`` (the agent's asks for clarification, one
object ``{"t", "progress", "answered", "instruction_id"}`` each: :class:`~icrsumo.core.types.Ask`).
Malformed input raises :class:`~icrsumo.core.errors.InputError`
naming the key.
"""

from __future__ import annotations

import json
import math
import operator
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from icrsumo.core.doccheck import DocChecker
from icrsumo.core.errors import KIND_NAMES, Field, InputError, short
from icrsumo.core.fsio import dumps_json, read_text, write_atomic
from icrsumo.core.types import (
    TERMINATIONS,
    Ask,
    EpisodeLog,
    EpisodeResult,
    Event,
    GuardDecision,
    Infraction,
    ModelCall,
    TerminationClass,
)
from icrsumo.core.vocab import EventKind, Family, Intent, Termination, Verdict

LOG_VERSION = 2

#: per-step column -> decimals (None: integer column)
STEP_COLUMNS: dict[str, int | None] = {
    "t": 3,
    "x": 2,
    "y": 2,
    "yaw": 4,
    "speed": 3,
    "progress": 2,
    "instruction": None,
    "outside": None,
    "route_dist": 2,
    "traffic_speed": 3,
    "speed_limit": 2,
}

#: columns a log may leave empty (not recorded)
OPTIONAL_COLUMNS = ("traffic_speed", "speed_limit")

#: event fields in stored order -> decimals (None: string)
EVENT_FIELDS: dict[str, int | None] = {"kind": None, "t": 3, "pos": 2, "other": None, "x": 2, "y": 2}

_HEADER = ("version", "route_id", "agent", "family", "k", "seed", "step_length", "route_length",
           "termination", "termination_t", "message", "route", "steps", "events", "model_calls", "guard",
           "asks")

#: the fields of one entry of ``asks`` (an object each), in stored order
ASK_FIELDS = ("t", "progress", "answered", "instruction_id")

#: the fields of one entry of ``guard`` (an object each), in stored order
GUARD_FIELDS = ("t", "progress", "instruction_id", "verdict", "reason")
#: the fields of a repair's entry of ``guard``: the text shown instead and the id of the baseline
#: instruction whose words it is (-1: the guard's own text, or "Follow the road.")
REPAIR_FIELDS = (*GUARD_FIELDS, "text", "baseline_id")

#: the fields of one entry of ``model_calls`` (an object each), in stored order
CALL_FIELDS = ("t", "instruction_id", "at", "key", "prompt", "answer", "maneuver", "valid", "problem")

#: largest value of the per-step ``outside`` bits (OFF_LANES | WRONG_LANE | their 2.0 twins)
_OUTSIDE_MAX = 15

_DEFAULT_SOURCE = "<episode log>"


def _r(value: float, decimals: int, name: str) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"episode log: {name} is not finite ({v!r})")
    return round(v, decimals) + 0.0  # + 0.0 turns -0.0 into 0.0


def log_to_dict(log: EpisodeLog) -> dict[str, Any]:
    """The log as plain JSON types, keys in fixed order, floats rounded. Raises ValueError for
    non-finite numbers or columns of unequal length."""
    n = len(log.t)
    steps: dict[str, list] = {}
    for col, dec in STEP_COLUMNS.items():
        values = getattr(log, col)
        if len(values) != n and not (col in OPTIONAL_COLUMNS and not values):
            raise ValueError(f"episode log: column {col!r} has {len(values)} entries, t has {n}")
        if dec is None:
            steps[col] = [int(v) for v in values]
        else:
            steps[col] = [_r(v, dec, f"steps.{col}[{i}]") for i, v in enumerate(values)]
    events = [
        [e.kind, _r(e.t, 3, f"events[{i}].t"), _r(e.pos, 2, f"events[{i}].pos"), e.other,
         _r(e.x, 2, f"events[{i}].x"), _r(e.y, 2, f"events[{i}].y")]
        for i, e in enumerate(log.events)
    ]
    return {
        "version": LOG_VERSION,
        "route_id": log.route_id,
        "agent": log.agent,
        "family": log.family,
        "k": int(log.k),
        "seed": int(log.seed),
        "step_length": _r(log.step_length, 6, "step_length"),
        "route_length": _r(log.route_length, 2, "route_length"),
        "termination": log.termination,
        "termination_t": _r(log.termination_t, 3, "termination_t"),
        "message": log.message,
        "route": [[_r(p[0], 2, f"route[{i}]"), _r(p[1], 2, f"route[{i}]")]
                  + ([_r(p[2], 4, f"route[{i}]")] if len(p) > 2 else []) for i, p in enumerate(log.route)],
        "steps": steps,
        "events": events,
        **({"model_calls": [_call_to_dict(c, i) for i, c in enumerate(log.model_calls)]}
           if log.model_calls else {}),
        **({"guard": [_guard_to_dict(g, i) for i, g in enumerate(log.guard)]} if log.guard else {}),
        **({"asks": [_ask_to_dict(a, i) for i, a in enumerate(log.asks)]} if log.asks else {}),
    }


def ask_counts(log: EpisodeLog) -> tuple[int, int]:
    """(asks, answered) of an episode: every ask for clarification the agent made, and how many
    the navigator answered (at most one per maneuver). (0, 0) without asking."""
    return len(log.asks), sum(a.answered for a in log.asks)


def _ask_to_dict(a: Ask, i: int) -> dict[str, Any]:
    return {"t": _r(a.t, 3, f"asks[{i}].t"), "progress": _r(a.progress, 2, f"asks[{i}].progress"),
            "answered": bool(a.answered), "instruction_id": int(a.instruction_id)}


def _entries(rd: _LogChecker, raw: Any, name: str, fields: tuple[str, ...], flag: str
             ) -> Iterator[tuple[str, dict]]:
    """(place, entry) of the list ``raw`` under key ``name``: each entry an object with exactly
    ``fields``, its ``flag`` true or false."""
    rd.lst(raw, name)
    for i, e in enumerate(raw):
        at = f"{name}[{i}]"
        if not isinstance(e, dict) or set(e) != set(fields):
            raise rd.fail(at, f"expected an object with keys {', '.join(fields)}")
        if not isinstance(e[flag], bool):
            raise rd.fail(f"{at}.{flag}", f"expected true or false, got {short(e[flag])}")
        yield at, e


def _asks_from(rd: _LogChecker, raw: Any) -> tuple[Ask, ...]:
    out = []
    for at, a in _entries(rd, raw, "asks", ASK_FIELDS, "answered"):
        out.append(Ask(t=rd.number(a["t"], f"{at}.t"), progress=rd.number(a["progress"], f"{at}.progress"),
                       answered=a["answered"],
                       instruction_id=rd.integer(a["instruction_id"], f"{at}.instruction_id")))
    return tuple(out)


def _call_to_dict(c: ModelCall, i: int) -> dict[str, Any]:
    return {"t": _r(c.t, 3, f"model_calls[{i}].t"), "instruction_id": int(c.instruction_id), "at": c.at,
            "key": c.key, "prompt": c.prompt, "answer": c.answer, "maneuver": str(c.maneuver),
            "valid": bool(c.valid), "problem": c.problem}


def _guard_to_dict(g: GuardDecision, i: int) -> dict[str, Any]:
    repair = {"text": g.text, "baseline_id": int(g.baseline_id)} if g.verdict == Verdict.REPAIR else {}
    return {"t": _r(g.t, 3, f"guard[{i}].t"), "progress": _r(g.progress, 2, f"guard[{i}].progress"),
            "instruction_id": int(g.instruction_id), "verdict": str(g.verdict), "reason": g.reason, **repair}


def _guard_from(rd: _LogChecker, raw: Any) -> tuple[GuardDecision, ...]:
    rd.lst(raw, "guard")
    out = []
    for i, g in enumerate(raw):
        at = f"guard[{i}]"
        repair = isinstance(g, dict) and g.get("verdict") == Verdict.REPAIR
        keys = REPAIR_FIELDS if repair else GUARD_FIELDS
        if not isinstance(g, dict) or set(g) != set(keys):
            raise rd.fail(at, f"expected an object with keys {', '.join(keys)}")
        try:
            verdict = Verdict(g["verdict"])
        except ValueError:
            raise rd.fail(f"{at}.verdict",
                          f"expected pass, block or repair, got {short(g['verdict'])}") from None
        out.append(GuardDecision(
            t=rd.number(g["t"], f"{at}.t"), progress=rd.number(g["progress"], f"{at}.progress"),
            instruction_id=rd.integer(g["instruction_id"], f"{at}.instruction_id"), verdict=verdict,
            reason=rd.string(g["reason"], f"{at}.reason"),
            **({"text": rd.string(g["text"], f"{at}.text"),
                "baseline_id": rd.integer(g["baseline_id"], f"{at}.baseline_id")} if repair else {})))
    return tuple(out)


def _calls_from(rd: _LogChecker, raw: Any) -> tuple[ModelCall, ...]:
    out = []
    for at, c in _entries(rd, raw, "model_calls", CALL_FIELDS, "valid"):
        out.append(ModelCall(
            t=rd.number(c["t"], f"{at}.t"),
            instruction_id=rd.integer(c["instruction_id"], f"{at}.instruction_id"),
            at=rd.string(c["at"], f"{at}.at"), key=rd.string(c["key"], f"{at}.key"),
            prompt=rd.string(c["prompt"], f"{at}.prompt"), answer=rd.string(c["answer"], f"{at}.answer"),
            maneuver=rd.member(c["maneuver"], f"{at}.maneuver", Intent, "maneuver"), valid=c["valid"],
            problem=rd.string(c["problem"], f"{at}.problem")))
    return tuple(out)


def _key(name: str) -> str:
    """A key of the file as a place in a message (cut short when long)."""
    return name if len(name) <= 40 else short(name)


class _LogChecker(DocChecker):
    """The typed reads of :class:`~icrsumo.core.doccheck.DocChecker`, worded as episode logs' and
    results' messages are (``k: expected an integer, got '1'``): a missing key named by its
    path, no fix but for a missing key, strings of any length."""

    max_string = None
    choice_fix = "one of {}"

    def __init__(self, source: str) -> None:
        super().__init__(source, "")

    def wrong_type(self, v: Any, place: str, kind: type) -> InputError:
        got = short(v) if kind is int else type(v).__name__
        return self.fail(place, f"expected {KIND_NAMES[kind]}, got {got}")

    def bad_number(self, v: Any, place: str) -> InputError:
        return self.fail(place, f"expected a finite number, got {short(v)}")

    def missing(self, key: str, prefix: str) -> InputError:
        return self.fail(f"{prefix}.{key}" if prefix else key, f"missing key {key!r}",
                         "write episode logs with icrsumo.results.logs")


_INTS, _NUMBERS = frozenset((int,)), frozenset((int, float))


def _column(rd: _LogChecker, raw: list, col: str, integers: bool) -> tuple:
    """The values of step column ``col`` read from its JSON list ``raw``: integers, or finite
    numbers as floats. A column of plain ints (and floats) is read at once; anything else goes
    value by value through the checker, which names the first bad entry."""
    if set(map(type, raw)) <= (_INTS if integers else _NUMBERS):
        if integers:
            return tuple(raw)
        try:
            values = tuple(map(float, raw))
        except OverflowError:  # an int too large for a float: the checker names it
            values = None
        if values is not None and all(map(math.isfinite, values)):
            return values
    conv = rd.integer if integers else rd.number
    return tuple(conv(v, f"steps.{col}[{i}]") for i, v in enumerate(raw))


def log_from_dict(d: Any, source: str = _DEFAULT_SOURCE) -> EpisodeLog:
    """Build an :class:`EpisodeLog` from :func:`log_to_dict` output, checking every key.
    ``source`` (a file name) is used in error messages."""
    rd = _LogChecker(source)
    if not isinstance(d, dict):
        raise rd.fail("", f"an episode log must be a JSON object, got {type(d).__name__}")
    unknown = sorted(set(d) - set(_HEADER))
    if unknown:
        raise rd.fail(_key(unknown[0]), f"unknown key {short(unknown[0])}",
                      f"allowed keys: {', '.join(_HEADER)}")
    version = rd.integer(rd.key(d, "version"), "version")
    if version != LOG_VERSION:
        fix = (f"expected {LOG_VERSION}; logs of version 1 predate the leaderboard's scoring rules "
               f"and cannot be rescored: run the episodes again with this icrsumo into a new "
               f"{Field('out')} folder")
        raise rd.fail("version", f"unsupported episode log version {short(version)}", fix)
    termination = rd.member(rd.key(d, "termination"), "termination", Termination, "termination")
    step_length = rd.number(rd.key(d, "step_length"), "step_length")
    if step_length <= 0:
        raise rd.fail("step_length", f"step_length must be > 0, got {step_length}")
    route_length = rd.number(rd.key(d, "route_length"), "route_length")
    if route_length < 0:
        raise rd.fail("route_length", f"route_length must be >= 0, got {route_length}")

    steps = rd.key(d, "steps")
    if not isinstance(steps, dict):
        raise rd.fail("steps", "expected an object of per-step columns")
    extra = sorted(set(steps) - set(STEP_COLUMNS))
    if extra:
        raise rd.fail(f"steps.{_key(extra[0])}", f"unknown column {short(extra[0])}",
                      f"allowed columns: {', '.join(STEP_COLUMNS)}")
    cols: dict[str, tuple] = {}
    for col, dec in STEP_COLUMNS.items():
        raw = rd.lst(rd.key(steps, col, "steps"), f"steps.{col}")
        cols[col] = _column(rd, raw, col, dec is None)
    n = len(cols["t"])
    for col, values in cols.items():
        if len(values) != n and not (col in OPTIONAL_COLUMNS and not values):
            raise rd.fail(f"steps.{col}", f"has {len(values)} entries but steps.t has {n}",
                          "all step columns must have equal length")
    t, progress = cols["t"], cols["progress"]
    if not (all(map(operator.lt, t, t[1:])) and all(map(operator.le, progress, progress[1:]))):
        for i in range(1, n):
            if t[i] <= t[i - 1]:
                raise rd.fail(f"steps.t[{i}]", f"time {t[i]} is not after {t[i - 1]}",
                              "step times must increase")
            if progress[i] < progress[i - 1]:
                raise rd.fail(f"steps.progress[{i}]", "progress decreased",
                              "progress is the furthest route position reached, so it never decreases")
    outside = cols["outside"]
    if outside and not (min(outside) >= 0 and max(outside) <= _OUTSIDE_MAX):
        for i, v in enumerate(outside):
            if not 0 <= v <= _OUTSIDE_MAX:
                raise rd.fail(f"steps.outside[{i}]", f"expected 0 to {_OUTSIDE_MAX}, got {short(v)}")
    raw_route = rd.key(d, "route")
    if not isinstance(raw_route, list) or (n and not raw_route):
        raise rd.fail("route", "expected a non-empty list of [x, y] points")
    route = []
    width = len(raw_route[0]) if raw_route and isinstance(raw_route[0], list) else 2
    for i, p in enumerate(raw_route):
        if not isinstance(p, list) or len(p) != width or width not in (2, 3):
            raise rd.fail(f"route[{i}]", f"expected [x, y] or [x, y, heading] like route[0], got {short(p)}")
        route.append(tuple(rd.number(v, f"route[{i}][{j}]") for j, v in enumerate(p)))

    raw_events = rd.lst(rd.key(d, "events"), "events")
    events = []
    for i, ev in enumerate(raw_events):
        if not isinstance(ev, list) or len(ev) != len(EVENT_FIELDS):
            raise rd.fail(f"events[{i}]", f"expected a list [{', '.join(EVENT_FIELDS)}], got {short(ev)}")
        kind = rd.member(ev[0], f"events[{i}].kind", EventKind, "event kind")
        events.append(Event(
            kind=kind,
            t=rd.number(ev[1], f"events[{i}].t"),
            pos=rd.number(ev[2], f"events[{i}].pos"),
            other=rd.string(ev[3], f"events[{i}].other"),
            x=rd.number(ev[4], f"events[{i}].x"),
            y=rd.number(ev[5], f"events[{i}].y"),
        ))

    return EpisodeLog(
        route_id=rd.string(rd.key(d, "route_id"), "route_id"),
        agent=rd.string(rd.key(d, "agent"), "agent"),
        family=rd.member(rd.key(d, "family"), "family", Family, "family"),
        k=rd.integer(rd.key(d, "k"), "k"),
        seed=rd.integer(rd.key(d, "seed"), "seed"),
        step_length=step_length,
        route_length=route_length,
        t=cols["t"],
        x=cols["x"],
        y=cols["y"],
        yaw=cols["yaw"],
        speed=cols["speed"],
        progress=cols["progress"],
        instruction=cols["instruction"],
        outside=cols["outside"],
        route_dist=cols["route_dist"],
        events=tuple(events),
        termination=termination,
        termination_t=rd.number(rd.key(d, "termination_t"), "termination_t"),
        message=rd.string(d.get("message", ""), "message"),
        route=tuple(route),
        traffic_speed=cols["traffic_speed"],
        speed_limit=cols["speed_limit"],
        model_calls=_calls_from(rd, d["model_calls"]) if "model_calls" in d else (),
        guard=_guard_from(rd, d["guard"]) if "guard" in d else (),
        asks=_asks_from(rd, d["asks"]) if "asks" in d else (),
    )


def dumps_log(log: EpisodeLog) -> str:
    """Canonical JSON text of a log (one line per column, one line per event)."""
    return dumps_json(log_to_dict(log))


def loads_log(text: str, source: str = _DEFAULT_SOURCE) -> EpisodeLog:
    """Parse :func:`dumps_log` output; malformed text raises InputError."""
    try:
        d = json.loads(text)
    except json.JSONDecodeError as err:
        place = f"line {err.lineno} column {err.colno}"
        raise InputError(source, place, f"not valid JSON: {err.msg}") from None
    except RecursionError:
        raise InputError(source, "", "not valid JSON: nested too deeply",
                         "write episode logs with icrsumo.results.logs") from None
    return log_from_dict(d, source)


def write_log(path: Path | str, log: EpisodeLog) -> None:
    """Write a log atomically as canonical JSON."""
    write_atomic(Path(path), dumps_log(log))


def read_log(path: Path | str) -> EpisodeLog:
    """Read a log written by :func:`write_log`."""
    path = Path(path)
    if not path.is_file():
        why = "it is a folder" if path.is_dir() else "no such file"
        raise InputError(str(path), "", f"cannot read episode log: {why}", "check the path")
    text = read_text(path, "episode log", "write episode logs with icrsumo.results.logs")
    return loads_log(text, str(path))


def result_to_dict(result: EpisodeResult) -> dict[str, Any]:
    """An :class:`EpisodeResult` as plain JSON types (IS under the key ``"is"``; infractions as
    ``[kind, factor, t, pos, other]`` lists)."""
    return {
        "route_id": result.route_id,
        "agent": result.agent,
        "family": result.family,
        "k": int(result.k),
        "rc": float(result.rc),
        "is": float(result.is_),
        "ds": float(result.ds),
        "termination": result.termination,
        "termination_class": TerminationClass(result.termination_class).value,
        "outside_lanes_pct": float(result.outside_lanes_pct),
        "duration": float(result.duration),
        "outside_m": float(result.outside_m),
        "infractions": [[i.kind, float(i.factor), float(i.t), float(i.pos), i.other]
                        for i in result.infractions],
    }


def result_from_dict(d: Any, source: str = "<episode result>") -> EpisodeResult:
    """Inverse of :func:`result_to_dict`; malformed input raises InputError."""
    rd = _LogChecker(source)
    if not isinstance(d, dict):
        raise rd.fail("", f"an episode result must be a JSON object, got {type(d).__name__}")
    termination = rd.member(rd.key(d, "termination"), "termination", Termination, "termination")
    cls = rd.string(rd.key(d, "termination_class"), "termination_class")
    if cls != TERMINATIONS[termination].value:
        raise rd.fail("termination_class", f"{short(cls)} does not match termination {termination!r}")
    raw = rd.key(d, "infractions")
    if not isinstance(raw, list):
        raise rd.fail("infractions", "expected a list")
    infractions = []
    for i, it in enumerate(raw):
        if not isinstance(it, list) or len(it) != 5:
            raise rd.fail(f"infractions[{i}]", f"expected [kind, factor, t, pos, other], got {short(it)}")
        infractions.append(Infraction(
            kind=rd.member(it[0], f"infractions[{i}].kind", EventKind, "event kind"),
            factor=rd.number(it[1], f"infractions[{i}].factor"),
            t=rd.number(it[2], f"infractions[{i}].t"),
            pos=rd.number(it[3], f"infractions[{i}].pos"),
            other=rd.string(it[4], f"infractions[{i}].other"),
        ))
    return EpisodeResult(
        route_id=rd.string(rd.key(d, "route_id"), "route_id"),
        agent=rd.string(rd.key(d, "agent"), "agent"),
        family=rd.member(rd.key(d, "family"), "family", Family, "family"),
        k=rd.integer(rd.key(d, "k"), "k"),
        rc=rd.number(rd.key(d, "rc"), "rc"),
        is_=rd.number(rd.key(d, "is"), "is"),
        ds=rd.number(rd.key(d, "ds"), "ds"),
        termination=termination,
        termination_class=TERMINATIONS[termination],
        infractions=tuple(infractions),
        outside_lanes_pct=rd.number(rd.key(d, "outside_lanes_pct"), "outside_lanes_pct"),
        duration=rd.number(rd.key(d, "duration"), "duration"),
        outside_m=rd.number(d.get("outside_m", 0.0), "outside_m"),
    )
