"""LangAuto's own baseline wording: ``--baseline-bank FILE`` (``generate`` and ``evaluate``).

ICR-Drive's baseline x0 is LangAuto's instruction text. LMDrive (github.com/opendilab/LMDrive,
Apache-2.0) ships it as an instruction dictionary: one JSON object mapping LangAuto's 65
instruction-type ids, as strings ``"0"`` .. ``"64"``, to lists of phrasings, with ``[x]`` (a
distance in metres) and ``[y]`` (a lateral offset, id 64 only) as placeholders. icrsumo does not
ship those sentences; a user who has them passes the file, and the baseline sequences then use
its phrasings for the instruction types that :data:`LANGAUTO_IDS` maps. Every other type keeps
icrsumo's own phrasing (``templates/baseline.json``).

The file is validated up front (:func:`load_baseline_bank`): UTF-8 JSON, an object whose keys
are ``"0"`` .. ``"64"`` and whose values are non-empty lists of non-empty strings, with no
placeholder but ``[x]`` and ``[y]``; a phrasing of a mapped id carries ``[x]`` exactly when its
icrsumo type has a distance, and never ``[y]``. Each problem is one
:class:`~icrsumo.core.errors.InputError` line. Phrasings that icrsumo's intent classifier does not
read as their maneuver (a left turn read as a lane change, say) are set aside, as icrsumo's own
bank would refuse them: the counterfactual families and the instruction-following agent read
the baseline text through the classifier. They are listed in :attr:`BaselineBank.set_aside`;
a type whose phrasings are all set aside keeps icrsumo's wording.

The choice is deterministic: a second Generator seeded with the route seed draws the phrasing
(:mod:`.baseline`), so the same file and seed give the same text, and the sequence's layout and
icrsumo's own draws are those without the bank. :attr:`BaselineBank.sha256` (the file's bytes)
goes into the instruction files and into an evaluation folder's ``config.json``.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from icrsumo.core.errors import Field, InputError
from icrsumo.core.fsio import check_surrogates, no_constants, no_duplicates
from icrsumo.core.types import Intent

from .banks import BASELINE_TYPES, ORDINALS
from .intent import classify_intent

__all__ = ["LANGAUTO_IDS", "LANGAUTO_MEANINGS", "BaselineBank", "SetAside", "langauto_id",
           "load_baseline_bank"]

#: LangAuto's 65 instruction types (LMDrive's ``instruction_dict.json`` keys; the order of
#: ``tools/data_parsing/parse_instruction.py``'s rule list there): id -> what it asks.
LANGAUTO_MEANINGS: dict[str, str] = {
    "0": "turn left just ahead", "1": "turn right just ahead",
    "2": "turn left after [x] m", "3": "turn right after [x] m",
    "4": "turn left at the next intersection", "5": "turn right at the next intersection",
    "6": "go straight at the next intersection",
    "7": "turn left at the intersection after [x] m", "8": "turn right at the intersection after [x] m",
    "9": "go straight at the intersection after [x] m",
    "10": "turn left at the next traffic light", "11": "turn right at the next traffic light",
    "12": "go straight at the next traffic light",
    "13": "turn left at the traffic light after [x] m", "14": "turn right at the traffic light after [x] m",
    "15": "go straight at the traffic light after [x] m",
    "16": "turn left at the next T-junction", "17": "turn right at the next T-junction",
    "18": "go straight at the next T-junction",
    "19": "turn left at the T-junction after [x] m", "20": "turn right at the T-junction after [x] m",
    "21": "go straight at the T-junction after [x] m",
    "22": "roundabout: take the first exit", "23": "roundabout: take the second exit",
    "24": "roundabout: take the third exit",
    "25": "left here, then left at the next intersection",
    "26": "left here, then right at the next intersection",
    "27": "left here, then straight at the next intersection",
    "28": "right here, then left at the next intersection",
    "29": "right here, then right at the next intersection",
    "30": "right here, then straight at the next intersection",
    "31": "straight here, then left at the next intersection",
    "32": "straight here, then right at the next intersection",
    "33": "straight here, then straight at the next intersection",
    "34": "change to the left lane", "35": "change to the right lane",
    "36": "change to the left lane in [x] m", "37": "change to the right lane in [x] m",
    "38": "follow this road", "39": "follow the highway",
    "40": "follow this road for [x] m", "41": "follow the highway for [x] m",
    "42": "keep your course straight", "43": "keep straight until the next intersection",
    "44": "keep straight for [x] m", "45": "keep straight for [x] m until the next intersection",
    "46": "move left to enter the highway", "47": "move right to exit the highway",
    "48": "in [x] m, move left (highway)", "49": "in [x] m, move right to exit the highway",
    "50": "notice: pedestrians ahead", "51": "notice: bicycle ahead",
    "52": "notice: vehicle stopping suddenly ahead", "53": "notice: vehicle running a red light on the left",
    "54": "notice: vehicle running a red light ahead", "55": "notice: rough road ahead",
    "56": "notice: tunnel ahead", "57": "notice: red light ahead", "58": "notice: green light ahead",
    "59": "notice: yellow light ahead",
    "60": "start driving", "61": "slow down", "62": "stop", "63": "drive freely",
    "64": "go to the navigation point [x] m ahead and [y] m to the left/right",
}

#: icrsumo baseline instruction type -> LangAuto id, per slot value where the type has one
#: (``{dir}`` / ``{side}``: left, right; ``{exit}``: first, second, third). Types that are not
#: here (highway_enter, notice_traffic_light, notice_stop_sign) and slot values that are not
#: (a fourth roundabout exit) keep icrsumo's phrasing. The README's table says why each id.
LANGAUTO_IDS: dict[str, str | dict[str, str]] = {
    "start": "60",
    "follow": "38",
    "follow_distance": "40",
    "follow_highway": "39",
    "follow_highway_distance": "41",
    "turn": {"left": "0", "right": "1"},
    "turn_distance": {"left": "2", "right": "3"},
    "turn_intersection": {"left": "4", "right": "5"},
    "turn_stop_sign": {"left": "4", "right": "5"},  # LangAuto has no stop-sign type
    "turn_traffic_light": {"left": "10", "right": "11"},
    "turn_t_junction": {"left": "16", "right": "17"},
    "straight": "6",
    "straight_distance": "9",
    "straight_intersection": "6",
    "straight_traffic_light": "12",
    "straight_stop_sign": "6",  # LangAuto has no stop-sign type
    "roundabout_exit": {"first": "22", "second": "23", "third": "24"},
    "lane_change": {"left": "34", "right": "35"},
    "lane_change_distance": {"left": "36", "right": "37"},
    "highway_exit": "47",
    "highway_exit_distance": "49",
    "notice_pedestrians": "50",
}

#: the largest file read (LMDrive's dictionary has about 32 kB)
MAX_BYTES = 4 << 20
MAX_TEXT = 300
_KEY = re.compile(r"0|[1-9][0-9]?")
_PLACEHOLDER = re.compile(r"\[[^\[\]{}]*\]|\{[^\[\]{}]*\}")
_VALID = ("[x]", "[y]")


def _slot_value(slots: Mapping[str, str]) -> str:
    return slots.get("dir") or slots.get("side") or slots.get("exit") or ""


def langauto_id(itype: str, slots: Mapping[str, str] | None = None) -> str | None:
    """The LangAuto id that stands for icrsumo's instruction type ``itype`` with ``slots``
    (e.g. ``{"dir": "left"}``), or None when LangAuto has no counterpart."""
    entry = LANGAUTO_IDS.get(itype)
    if isinstance(entry, dict):
        return entry.get(_slot_value(slots or {}))
    return entry


def _mapped() -> dict[str, list[tuple[str, str]]]:
    """LangAuto id -> the (icrsumo type, slot value) pairs it stands for."""
    out: dict[str, list[tuple[str, str]]] = {}
    for itype, entry in LANGAUTO_IDS.items():
        pairs = entry.items() if isinstance(entry, dict) else [("", entry)]
        for value, lid in pairs:
            out.setdefault(lid, []).append((itype, value))
    return out


_MAPPED = _mapped()


def _wanted(itype: str, value: str) -> Intent | None:
    """The intent a phrasing of ``itype`` with slot ``value`` must read as (None: a notice)."""
    if itype.startswith("notice_"):
        return None
    rule = BASELINE_TYPES[itype]
    if rule == "{exit}":
        from .maneuvers import roundabout_intent  # lazily: maneuvers imports the network code

        return roundabout_intent(ORDINALS.index(value) + 1)
    return Intent(rule.format(dir=value, side=value))


@dataclass(frozen=True)
class SetAside:
    """A phrasing of the file that the baseline does not use: LangAuto id ``id``, its index in
    that id's list, the text, what the classifier reads and the intent its type needs."""

    id: str
    index: int
    text: str
    classified: Intent
    wanted: Intent

    def line(self) -> str:
        return (f'"{self.id}"[{self.index}]: {self.text!r} reads as {self.classified.value}, '
                f"not {self.wanted.value}")


@dataclass(frozen=True)
class BaselineBank:
    """A validated LangAuto-style instruction dictionary. ``phrasings``: id -> every phrasing
    of the file; ``usable``: (icrsumo type, slot value) -> the phrasings the baseline draws
    from; ``sha256``: of the file's bytes."""

    path: Path
    sha256: str
    phrasings: Mapping[str, tuple[str, ...]] = field(repr=False)
    usable: Mapping[tuple[str, str], tuple[str, ...]] = field(repr=False)
    set_aside: tuple[SetAside, ...] = ()

    def phrasings_for(self, itype: str, slots: Mapping[str, str] | None = None) -> tuple[str, ...] | None:
        """The phrasings of the file for ``itype`` with ``slots``, or None when icrsumo's own
        phrasing stays (no LangAuto counterpart, the id is not in the file, or all of its
        phrasings were set aside)."""
        if itype not in LANGAUTO_IDS:
            return None
        return self.usable.get((itype, _slot_value(slots or {}))) or None

    def note(self) -> str | None:
        """The one stderr line that says which phrasings are not used (None: all are)."""
        if not self.set_aside:
            return None
        n = len(self.set_aside)
        return (f"icrsumo: note: {self.path}: {n} phrasing{'s' if n > 1 else ''} set aside, read as "
                f"another maneuver (first: {self.set_aside[0].line()})")

    def describe(self) -> dict:
        """What the instruction index records about the bank."""
        return {"file": self.path.name, "sha256": self.sha256,
                "ids_used": sorted({lid for lid in _MAPPED if lid in self.phrasings}, key=int),
                "set_aside": [s.line() for s in self.set_aside]}


def _fail(path: Path, place: str, problem: str, fix: str) -> InputError:
    return InputError(path, place, problem, fix)


def _read(path: Path) -> tuple[bytes, str]:
    """The file's bytes and its text (UTF-8, an optional BOM)."""
    if not path.exists():
        raise _fail(path, "", "baseline bank not found", f"check the {Field('baseline_bank')} path")
    if not path.is_file():
        raise _fail(path, "", "is not a file", "pass LMDrive's instruction_dict.json (a JSON file)")
    size = path.stat().st_size
    if size > MAX_BYTES:
        raise _fail(path, "", f"file too large ({size} bytes, at most {MAX_BYTES})",
                    "pass an instruction dictionary (LMDrive's has about 32 kB)")
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise _fail(path, "", f"baseline bank cannot be read ({err.strerror or err})",
                    "check the file's permissions") from None
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")) or b"\x00" in raw:
        raise _fail(path, "encoding", "is UTF-16 (or holds NUL bytes), not UTF-8", "save the file as UTF-8")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise _fail(path, f"byte {err.start}", f"not UTF-8 (byte 0x{raw[err.start]:02x})",
                    "save the file as UTF-8") from None
    return raw, text


def _parse(path: Path, text: str) -> dict:
    try:
        data = json.loads(text, object_pairs_hook=no_duplicates, parse_constant=no_constants)
    except json.JSONDecodeError as err:
        raise _fail(path, f"line {err.lineno}, column {err.colno}", f"malformed JSON ({err.msg})",
                    "fix the JSON syntax") from None
    except ValueError as err:
        raise _fail(path, "", f"malformed JSON ({err})", "fix the JSON") from None
    except RecursionError:
        raise _fail(path, "", "malformed JSON (nested too deeply)", "fix the JSON") from None
    check_surrogates(data, text, path, "the baseline bank")
    if not isinstance(data, dict):
        raise _fail(path, "top level", f"must be a JSON object, not {type(data).__name__}",
                    'map LangAuto instruction-type ids "0" .. "64" to lists of phrasings')
    if not data:
        raise _fail(path, "top level", "holds no instruction types",
                    'map LangAuto instruction-type ids "0" .. "64" to lists of phrasings')
    return data


def _check_phrasing(path: Path, place: str, lid: str, text: object) -> str:
    if not isinstance(text, str) or not text.strip():
        raise _fail(path, place, "phrasing must be a non-empty string", "write the sentence")
    if len(text) > MAX_TEXT:
        raise _fail(path, place, f"phrasing longer than {MAX_TEXT} characters", "shorten it")
    if "\n" in text or "\r" in text:
        raise _fail(path, place, "phrasing spans several lines", "write it on one line")
    for token in _PLACEHOLDER.findall(text):
        if token not in _VALID:
            raise _fail(path, place, f"unknown placeholder {token}",
                        "LangAuto phrasings use only [x] (a distance) and [y]")
    if any(ch in _PLACEHOLDER.sub("", text) for ch in "[]{}"):
        raise _fail(path, place, "unbalanced bracket", "write placeholders as [x] or [y]")
    pairs = _MAPPED.get(lid)
    if pairs:
        itype = pairs[0][0]
        distance = itype.endswith("_distance")
        if "[y]" in text:
            raise _fail(path, place, f"uses [y], but id {lid} stands for icrsumo's {itype}, which has no [y]",
                        "drop [y] (only LangAuto's navigation-point id 64 has it)")
        if "[x]" in text and not distance:
            raise _fail(path, place, f"uses [x], but id {lid} stands for icrsumo's {itype}, which "
                        "carries no distance", "drop [x] from this phrasing")
        if distance and "[x]" not in text:
            raise _fail(path, place, f"lacks [x], but id {lid} stands for icrsumo's {itype}, which is "
                        "shown with a distance", "put [x] where the distance in metres goes")
    return text.strip()


def load_baseline_bank(path: str | Path) -> BaselineBank:
    """Read and validate a LangAuto-style instruction dictionary (see the module docstring);
    an InputError naming the file and the place for the first problem. A file is read once
    while it is unchanged (options check it, the run then uses it)."""
    path = Path(path)
    try:
        st = path.stat()
    except OSError:
        return _load(path)  # names the problem
    return _load_cached(path, st.st_mtime_ns, st.st_size)


@lru_cache(maxsize=8)
def _load_cached(path: Path, mtime_ns: int, size: int) -> BaselineBank:
    return _load(path)


def _load(path: Path) -> BaselineBank:
    raw, text = _read(path)
    data = _parse(path, text)
    phrasings: dict[str, tuple[str, ...]] = {}
    for lid, items in data.items():
        if not _KEY.fullmatch(lid) or int(lid) > 64:
            raise _fail(path, f"key {lid!r}", "not a LangAuto instruction-type id",
                        'use the ids "0" .. "64", as strings')
        if not isinstance(items, list) or not items:
            raise _fail(path, f'"{lid}"', "must be a non-empty list of phrasings",
                        f'write "{lid}": ["...", ...]')
        phrasings[lid] = tuple(_check_phrasing(path, f'"{lid}"[{i}]', lid, t) for i, t in enumerate(items))
    usable: dict[tuple[str, str], tuple[str, ...]] = {}
    aside: dict[tuple[str, int], SetAside] = {}
    for lid, pairs in _MAPPED.items():
        for itype, value in pairs:
            if lid not in phrasings:
                continue
            want = _wanted(itype, value)
            keep = []
            for i, t in enumerate(phrasings[lid]):
                got = classify_intent(t) if want is not None else None
                if want is None or got == want:
                    keep.append(t)
                else:
                    aside[(lid, i)] = SetAside(lid, i, t, got, want)
            usable[(itype, value)] = tuple(keep)
    order = sorted(aside, key=lambda k: (int(k[0]), k[1]))
    return BaselineBank(path=path, sha256=hashlib.sha256(raw).hexdigest(), phrasings=phrasings,
                        usable=usable, set_aside=tuple(aside[k] for k in order))
