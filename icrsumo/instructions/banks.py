"""Template banks as data (``templates/*.json``): loading and up-front validation.

Files of a template folder:

- ``baseline.json``: LangAuto-style phrasings per instruction type (our own baseline bank);
- ``paraphrase.json`` (P[τ]) and ``misleading.json`` (M[τ]): per intent τ, ``plain`` entries and
  ``distance`` entries (with ``[x]``); left/right/straight entries may use ``{junction}``;
- ``ambiguity.json`` (A): one global list, no placeholders;
- ``noise.json`` (N): operations, each a list of primitives of :mod:`.noise`.

Every problem is an InputError naming the file and the entry.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from pathlib import Path

from icrsumo.core.errors import Field, InputError, expect, short
from icrsumo.core.fsio import read_json
from icrsumo.core.resources import data_dir
from icrsumo.core.types import Intent

from .intent import classify_intent
from .noise import PRIMITIVES

#: the smallest bank size per intent and form, so that K = 8 draws without replacement vary
MIN_ENTRIES = 12
#: intents that navigation instructions carry (the ones P and M banks must cover)
NAV_INTENTS = (Intent.LEFT, Intent.RIGHT, Intent.STRAIGHT, Intent.FOLLOW, Intent.LANE_LEFT,
               Intent.LANE_RIGHT)
#: what a misleading entry for intent τ must classify as
CONTRADICTS: dict[Intent, frozenset[Intent]] = {
    Intent.LEFT: frozenset({Intent.RIGHT}),
    Intent.RIGHT: frozenset({Intent.LEFT}),
    Intent.STRAIGHT: frozenset({Intent.LEFT, Intent.RIGHT}),
    Intent.FOLLOW: frozenset({Intent.LEFT, Intent.RIGHT}),
    Intent.LANE_LEFT: frozenset({Intent.LANE_RIGHT}),
    Intent.LANE_RIGHT: frozenset({Intent.LANE_LEFT}),
}
#: intents whose P/M entries may name the junction
JUNCTION_INTENTS = frozenset({Intent.LEFT, Intent.RIGHT, Intent.STRAIGHT})
#: the noun phrase that fills {junction}, by maneuver junction kind
JUNCTION_PHRASES = {
    "traffic_light": "the traffic light", "stop_sign": "the stop sign",
    "t_junction": "the T-junction", "crossroad": "the intersection",
    "roundabout": "the roundabout", "highway_exit": "the exit", "highway_entry": "the ramp",
    "junction": "the next junction", "": "the next junction",
}
#: instruction types of the baseline bank the generator needs, with their intent rule
BASELINE_TYPES: dict[str, str] = {
    "start": "follow", "follow": "follow", "follow_distance": "follow",
    "follow_highway": "follow", "follow_highway_distance": "follow",
    "turn": "{dir}", "turn_distance": "{dir}", "turn_intersection": "{dir}",
    "turn_traffic_light": "{dir}", "turn_t_junction": "{dir}", "turn_stop_sign": "{dir}",
    "straight": "straight", "straight_distance": "straight", "straight_intersection": "straight",
    "straight_traffic_light": "straight", "straight_stop_sign": "straight",
    "roundabout_exit": "{exit}", "lane_change": "lane_{side}", "lane_change_distance": "lane_{side}",
    "highway_enter": "follow", "highway_exit": "right", "highway_exit_distance": "right",
    "notice_traffic_light": "stop", "notice_stop_sign": "stop", "notice_pedestrians": "stop",
}
MIN_BASELINE = 6
_SLOT = re.compile(r"\{(\w+)\}")
ORDINALS = ("first", "second", "third", "fourth")


@dataclass(frozen=True)
class Entry:
    """One bank entry: its id and template text."""

    id: str
    text: str


@dataclass(frozen=True)
class Banks:
    """All template banks of one folder. ``sha256`` hashes the files' bytes."""

    folder: Path
    baseline: dict[str, tuple[str, ...]]
    paraphrase: dict[Intent, dict[str, tuple[Entry, ...]]]
    misleading: dict[Intent, dict[str, tuple[Entry, ...]]]
    ambiguity: tuple[Entry, ...]
    noise: tuple[tuple[str, tuple[str, ...]], ...]
    sha256: str


def fill(text: str, junction: str = "", **slots: str) -> str:
    """Fill ``{junction}`` (from a junction kind) and other ``{slot}``s; ``[x]`` stays."""
    values = {"junction": JUNCTION_PHRASES.get(junction, "the next junction"), **slots}
    return _SLOT.sub(lambda m: values.get(m.group(1), m.group(0)), text)


#: the ``format`` a bank file may declare, and the keys it may hold, by file
_FORMATS = {None: "icrsumo-baseline-bank/1"}
_TOP_KEYS = {"baseline": ("format", "types"), "paraphrase": ("format", "family", "intents"),
             "misleading": ("format", "family", "intents"), "ambiguity": ("format", "family", "entries"),
             "noise": ("format", "family", "operations")}
_FIX = "see templates/README.md for the bank format"


def _unknown(path: Path, place: str, d: dict, allowed, what: str = "key") -> None:
    """InputError for the first key of ``d`` that is not in ``allowed``."""
    extra = [k for k in d if k not in allowed]
    if extra:
        where = f"{place}.{extra[0]}" if place else extra[0]
        known = ", ".join(allowed) if len(allowed) <= 8 else \
            f"one of the {len(allowed)} {what}s of the bundled {path.name} (e.g. {', '.join(allowed[:3])})"
        raise InputError(path, where, f"unknown {what} {short(extra[0])}", f"use {known}")


def _load(path: Path, family: str | None) -> dict:
    if not path.exists():
        raise InputError(path, "", "template bank missing", f"add the file or drop {Field('templates')}")
    data = read_json(path, "template bank", "")
    expect(data, dict, path, "top level", "a template bank", _FIX)
    _unknown(path, "", data, _TOP_KEYS[family or "baseline"])
    fmt = _FORMATS.get(family, "icrsumo-bank/1")
    if "format" in data and data["format"] != fmt:
        raise InputError(path, "format", f"unsupported format {short(data['format'])} (expects {fmt})",
                         f'write "format": "{fmt}" or leave the key out')
    if family is not None and data.get("family") != family:
        raise InputError(path, "family", f"expected \"family\": \"{family}\"", "fix the family field")
    return data


def _check_text(path: Path, place: str, text: object) -> str:
    expect(text, str, path, place, "text", "write the sentence as a JSON string")
    if not text.strip():
        raise InputError(path, place, "text must be a non-empty string", "write the sentence")
    if len(text) > 300:
        raise InputError(path, place, "text longer than 300 characters", "shorten it")
    if "\n" in text or "\r" in text:
        raise InputError(path, place, "text spans several lines", "write it on one line")
    return text


def _load_baseline(folder: Path) -> dict[str, tuple[str, ...]]:
    path = folder / "baseline.json"
    data = _load(path, None)
    if "types" not in data:
        raise InputError(path, "types", "missing object 'types'", "see the README's bank format")
    types = expect(data["types"], dict, path, "types", "types", _FIX)
    _unknown(path, "types", types, tuple(BASELINE_TYPES), "instruction type")
    out = {}
    for tname, rule in BASELINE_TYPES.items():
        spec = types.get(tname)
        if spec is None:
            raise InputError(path, f"types.{tname}", "missing type or its 'phrasings' list",
                             f"add \"{tname}\": {{\"intent\": \"{rule}\", \"phrasings\": [...]}}")
        expect(spec, dict, path, f"types.{tname}", tname, _FIX)
        _unknown(path, f"types.{tname}", spec, ("intent", "phrasings"))
        if "intent" in spec and spec["intent"] != rule:
            raise InputError(path, f"types.{tname}.intent", f"is {short(spec['intent'])}, the type's rule is "
                             f"{rule!r}", f'write "intent": "{rule}" or leave the key out')
        if "phrasings" not in spec:
            raise InputError(path, f"types.{tname}", "missing type or its 'phrasings' list",
                             f"add \"{tname}\": {{\"intent\": \"{rule}\", \"phrasings\": [...]}}")
        phr = expect(spec["phrasings"], list, path, f"types.{tname}.phrasings", "phrasings", _FIX)
        if len(phr) < MIN_BASELINE:
            raise InputError(path, f"types.{tname}", f"has {len(phr)} phrasings, needs {MIN_BASELINE}",
                             "add phrasings")
        for i, text in enumerate(phr):
            place = f"types.{tname}.phrasings[{i}]"
            _check_text(path, place, text)
            has_x = "[x]" in text
            if has_x != tname.endswith("_distance"):
                raise InputError(path, place, f"{'has' if has_x else 'lacks'} the placeholder [x]",
                                 "only *_distance types carry [x], and all of their phrasings do")
            need = set(_SLOT.findall(rule))
            slots = set(_SLOT.findall(text))
            if slots != need:
                raise InputError(path, place, f"placeholders {sorted(slots)} but type needs {sorted(need)}",
                                 "use exactly the type's placeholders")
            if tname.startswith("notice_"):
                continue
            for fills in _fills(need):
                want = _exit_intent(fills["exit"]) if "exit" in fills else Intent(rule.format(**fills))
                got = classify_intent(fill(text, **fills))
                if got != want:
                    raise InputError(path, place, f"{fill(text, **fills)!r} classifies as {got.value}, "
                                     f"not {want.value}", "rephrase it so that the intent is clear")
        out[tname] = tuple(phr)
    return out


def baseline_catalogue(banks: Banks) -> tuple[tuple[str, str, Intent], ...]:
    """Every concrete baseline instruction of ``banks``: (template id, text, intent) for each
    maneuver type (notices and the start excluded), each phrasing and each slot value
    (left / right, the roundabout's ordinals), in the bank's order; ``[x]`` stays. The pool of
    the ``shuffled`` control family."""
    out = []
    for tname, rule in BASELINE_TYPES.items():
        if rule == "stop" or tname == "start" or tname not in banks.baseline:
            continue
        for i, phrasing in enumerate(banks.baseline[tname]):
            for fills in _fills(set(_SLOT.findall(rule))):
                intent = _exit_intent(fills["exit"]) if "exit" in fills else Intent(fill(rule, **fills))
                tid = ":".join([tname, str(i), *fills.values()])
                out.append((tid, fill(phrasing, **fills), intent))
    return tuple(out)


def _exit_intent(ordinal: str) -> Intent:
    from .maneuvers import roundabout_intent

    return roundabout_intent(ORDINALS.index(ordinal) + 1)


def _fills(slots: set[str]) -> list[dict[str, str]]:
    if "dir" in slots:
        return [{"dir": "left"}, {"dir": "right"}]
    if "side" in slots:
        return [{"side": "left"}, {"side": "right"}]
    if "exit" in slots:
        return [{"exit": o} for o in ORDINALS]
    return [{}]


def _entry(path: Path, place: str, e: object, seen: set[str]) -> Entry:
    """One ``{"id", "text"}`` bank entry, its id not in ``seen`` (which it joins)."""
    fix = 'write {"id": "...", "text": "..."}'
    expect(e, dict, path, place, "entry", fix)
    _unknown(path, place, e, ("id", "text"))
    if "id" not in e or "text" not in e:
        raise InputError(path, place, f"entry has no {'id' if 'id' not in e else 'text'}", fix)
    eid = expect(e["id"], str, path, f"{place}.id", "id", fix)
    if not eid.strip() or len(eid) > 100:
        raise InputError(path, f"{place}.id", "id must be 1 to 100 characters", "give a short id")
    text = _check_text(path, f"{place}.text", e["text"])
    if eid in seen:
        raise InputError(path, place, f"duplicate id {short(eid)}", "give every entry its own id")
    seen.add(eid)
    return Entry(eid, text)


def _entry_list(path: Path, place: str, value: object, what: str) -> list:
    """A list of at least MIN_ENTRIES bank entries (its items checked by the caller)."""
    if value is None:
        raise InputError(path, place, f"missing list of {what}", _FIX)
    expect(value, list, path, place, place.rsplit(".", 1)[-1], _FIX)
    if len(value) < MIN_ENTRIES:
        raise InputError(path, place, f"has {len(value)} entries, needs at least {MIN_ENTRIES}",
                         "add entries so that K draws without replacement vary")
    return value


def _load_intent_bank(folder: Path, family: str) -> dict[Intent, dict[str, tuple[Entry, ...]]]:
    path = folder / f"{family}.json"
    data = _load(path, family)
    if "intents" not in data:
        raise InputError(path, "intents", "missing object 'intents'", "see the README's bank format")
    intents = expect(data["intents"], dict, path, "intents", "intents", _FIX)
    _unknown(path, "intents", intents, tuple(t.value for t in NAV_INTENTS), "intent")
    out: dict[Intent, dict[str, tuple[Entry, ...]]] = {}
    seen: set[str] = set()
    for tau in NAV_INTENTS:
        spec = intents.get(tau.value)
        if spec is None:
            raise InputError(path, f"intents.{tau.value}", "missing intent", "add plain and distance lists")
        expect(spec, dict, path, f"intents.{tau.value}", tau.value,
               'write {"plain": [...], "distance": [...]}')
        _unknown(path, f"intents.{tau.value}", spec, ("plain", "distance"), "form")
        out[tau] = {}
        for form in ("plain", "distance"):
            place0 = f"intents.{tau.value}.{form}"
            entries = _entry_list(path, place0, spec.get(form), f"{form} entries")
            parsed = []
            for i, e in enumerate(entries):
                place = f"{place0}[{i}]"
                entry = _entry(path, place, e, seen)
                text = entry.text
                if text.count("[x]") != (1 if form == "distance" else 0):
                    raise InputError(path, place, f"{form} entries need [x] "
                                     f"{'exactly once' if form == 'distance' else 'zero times'}",
                                     "keep the distance placeholder as the form requires")
                slots = set(_SLOT.findall(text))
                allowed = {"junction"} if tau in JUNCTION_INTENTS else set()
                if slots - allowed:
                    raise InputError(path, place,
                                     f"unknown or disallowed placeholders {sorted(slots - allowed)}",
                                     "only left/right/straight entries may use {junction}")
                got = classify_intent(fill(text, "crossroad"))
                want = {tau} if family == "paraphrase" else CONTRADICTS[tau]
                if got not in want:
                    expected = " or ".join(sorted(w.value for w in want))
                    raise InputError(path, place, f"{text!r} classifies as {got.value}, not {expected}",
                                     "rephrase it so that the classifier recovers the intended direction")
                parsed.append(entry)
            out[tau][form] = tuple(parsed)
    return out


def _load_ambiguity(folder: Path) -> tuple[Entry, ...]:
    path = folder / "ambiguity.json"
    data = _load(path, "ambiguity")
    entries = _entry_list(path, "entries", data.get("entries"), "entries")
    out, seen = [], set()
    for i, e in enumerate(entries):
        place = f"entries[{i}]"
        entry = _entry(path, place, e, seen)
        text = entry.text
        if "[x]" in text or _SLOT.search(text):
            raise InputError(path, place, "ambiguity entries carry no placeholders", "remove them")
        got = classify_intent(text)
        if got != Intent.UNKNOWN:
            raise InputError(path, place, f"{text!r} still carries a direction ({got.value})",
                             "remove direction words so that no maneuver can be recovered")
        out.append(entry)
    return tuple(out)


def _load_noise(folder: Path) -> tuple[tuple[str, tuple[str, ...]], ...]:
    path = folder / "noise.json"
    data = _load(path, "noise")
    ops = data.get("operations")
    if ops is None:
        raise InputError(path, "operations", f"needs at least {MIN_ENTRIES} operations", "add operations")
    expect(ops, list, path, "operations", "operations", _FIX)
    if len(ops) < MIN_ENTRIES:
        raise InputError(path, "operations", f"needs at least {MIN_ENTRIES} operations", "add operations")
    out, seen = [], set()
    fix = 'write {"id": "...", "ops": [primitive, ...]}'
    for i, op in enumerate(ops):
        place = f"operations[{i}]"
        expect(op, dict, path, place, "operation", fix)
        _unknown(path, place, op, ("id", "ops"))
        if "id" not in op or "ops" not in op:
            raise InputError(path, place, f"operation has no {'id' if 'id' not in op else 'ops'}", fix)
        oid = expect(op["id"], str, path, f"{place}.id", "id", fix)
        prims = expect(op["ops"], list, path, f"{place}.ops", "ops", fix)
        if not oid.strip() or len(oid) > 100:
            raise InputError(path, f"{place}.id", "id must be 1 to 100 characters", "give a short id")
        if not prims:
            raise InputError(path, f"{place}.ops", "needs at least one primitive", fix)
        for j, p in enumerate(prims):
            expect(p, str, path, f"{place}.ops[{j}]", "primitive", f"use {', '.join(PRIMITIVES)}")
        bad = [p for p in prims if p not in PRIMITIVES]
        if bad:
            raise InputError(path, place, f"unknown primitive(s) {bad}",
                             f"use {', '.join(PRIMITIVES)}")
        if oid in seen:
            raise InputError(path, place, f"duplicate id {short(oid)}", "give every operation its own id")
        seen.add(oid)
        out.append((oid, tuple(prims)))
    return tuple(out)


def load_banks(folder: Path | None = None) -> Banks:
    """Load and validate every bank in ``folder`` (default: the bundled ``templates/``)."""
    folder = Path(folder) if folder is not None else data_dir("templates")
    if not folder.is_dir():
        raise InputError(folder, "", "template folder not found", f"check the {Field('templates')} path")
    baseline = _load_baseline(folder)  # each file is validated (and so readable) before it is hashed
    paraphrase = _load_intent_bank(folder, "paraphrase")
    misleading = _load_intent_bank(folder, "misleading")
    ambiguity = _load_ambiguity(folder)
    noise = _load_noise(folder)
    h = hashlib.sha256()
    for name in ("baseline", "paraphrase", "misleading", "ambiguity", "noise"):
        h.update(name.encode() + (folder / f"{name}.json").read_bytes())
    return Banks(folder=folder, baseline=baseline, paraphrase=paraphrase, misleading=misleading,
                 ambiguity=ambiguity, noise=noise, sha256=h.hexdigest())


def template_number(template_id: str) -> int | None:
    """The number a bank template id ends with (``M.left.p07`` -> 7), None without one."""
    digits = ""
    for c in reversed(template_id):
        if not c.isdigit():
            break
        digits = c + digits
    return int(digits) if digits else None
