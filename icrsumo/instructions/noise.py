"""Noise primitives of the Noise family: casing, punctuation and character typos.

Pure functions ``(text, rng) -> text``. The placeholder ``[x]`` is never touched. Typos hit one
alphabetic word of three or more letters, chosen at random (key words included, on purpose:
the family tests whether an agent still recovers the intent from a misspelt instruction).
"""

from __future__ import annotations

import re
from collections.abc import Callable

import numpy as np

from .lexicon import QWERTY_NEIGHBOURS

_PROTECTED = re.compile(r"\[x\]")
_WORD = re.compile(r"[A-Za-z]{3,}")

#: QWERTY neighbours of each letter (the classifier's spelling table)
KEYBOARD_NEIGHBOURS: dict[str, str] = QWERTY_NEIGHBOURS


def _segments(text: str) -> list[tuple[str, bool]]:
    """Split into (piece, protected) so that ``[x]`` stays intact."""
    out, last = [], 0
    for m in _PROTECTED.finditer(text):
        if m.start() > last:
            out.append((text[last:m.start()], False))
        out.append((m.group(0), True))
        last = m.end()
    if last < len(text):
        out.append((text[last:], False))
    return out


def _map_free(text: str, fn: Callable[[str], str]) -> str:
    return "".join(p if prot else fn(p) for p, prot in _segments(text))


def _match_case(new: str, old: str) -> str:
    return new.upper() if old.isupper() else new


def lower(text: str, rng: np.random.Generator) -> str:
    return _map_free(text, str.lower)


def upper(text: str, rng: np.random.Generator) -> str:
    return _map_free(text, str.upper)


def random_case(text: str, rng: np.random.Generator) -> str:
    """Each letter upper- or lower-case at random."""
    def fn(s: str) -> str:
        flips = rng.random(len(s)) < 0.5
        return "".join(c.upper() if f else c.lower() for c, f in zip(s, flips))
    return _map_free(text, fn)


def strip_punct(text: str, rng: np.random.Generator) -> str:
    """Drop punctuation (the placeholder's brackets survive)."""
    return _map_free(text, lambda s: re.sub(r"[.,;:!?'\"()-]", "", s)).strip()


def add_punct(text: str, rng: np.random.Generator) -> str:
    """Repeated or stray punctuation: '!!!', '...', ' ,' inserted."""
    endings = ("!!!", "...", "?!", " !!", ",,")
    end = endings[int(rng.integers(len(endings)))]
    return text.rstrip(".!?") + end


def _typo(text: str, rng: np.random.Generator, edit: Callable[[str, np.random.Generator], str]) -> str:
    """Apply ``edit`` to one random word (3+ letters) outside the placeholder."""
    spans = []
    offset = 0
    for piece, prot in _segments(text):
        if not prot:
            spans += [(offset + m.start(), offset + m.end()) for m in _WORD.finditer(piece)]
        offset += len(piece)
    if not spans:
        return text
    a, b = spans[int(rng.integers(len(spans)))]
    return text[:a] + edit(text[a:b], rng) + text[b:]


def _neighbour_edit(word: str, rng: np.random.Generator) -> str:
    i = int(rng.integers(len(word)))
    near = KEYBOARD_NEIGHBOURS.get(word[i].lower(), "")
    if not near:
        return word
    c = near[int(rng.integers(len(near)))]
    return word[:i] + _match_case(c, word[i]) + word[i + 1:]


def _transpose_edit(word: str, rng: np.random.Generator) -> str:
    i = int(rng.integers(len(word) - 1))
    return word[:i] + word[i + 1] + word[i] + word[i + 2:]


def _delete_edit(word: str, rng: np.random.Generator) -> str:
    i = int(rng.integers(len(word)))
    return word[:i] + word[i + 1:]


def _insert_edit(word: str, rng: np.random.Generator) -> str:
    i = int(rng.integers(len(word) + 1))
    base = word[min(i, len(word) - 1)].lower()
    near = KEYBOARD_NEIGHBOURS.get(base, "e")
    return word[:i] + near[int(rng.integers(len(near)))] + word[i:]


def _double_edit(word: str, rng: np.random.Generator) -> str:
    i = int(rng.integers(len(word)))
    return word[:i + 1] + word[i] + word[i + 1:]


def neighbour(text: str, rng: np.random.Generator) -> str:
    """One keyboard-neighbour substitution ('left' -> 'lwft')."""
    return _typo(text, rng, _neighbour_edit)


def transpose(text: str, rng: np.random.Generator) -> str:
    """Two adjacent letters swapped ('left' -> 'lfet')."""
    return _typo(text, rng, _transpose_edit)


def delete(text: str, rng: np.random.Generator) -> str:
    """One letter deleted ('right' -> 'rigt')."""
    return _typo(text, rng, _delete_edit)


def insert(text: str, rng: np.random.Generator) -> str:
    """One neighbouring letter inserted ('turn' -> 'turnm')."""
    return _typo(text, rng, _insert_edit)


def double(text: str, rng: np.random.Generator) -> str:
    """One letter doubled ('follow' -> 'folllow')."""
    return _typo(text, rng, _double_edit)


#: primitive name -> function; a noise operation in the bank is a list of these names
PRIMITIVES: dict[str, Callable[[str, np.random.Generator], str]] = {
    "lower": lower,
    "upper": upper,
    "random_case": random_case,
    "strip_punct": strip_punct,
    "add_punct": add_punct,
    "neighbour": neighbour,
    "transpose": transpose,
    "delete": delete,
    "insert": insert,
    "double": double,
}


def apply_ops(text: str, ops: list[str] | tuple[str, ...], rng: np.random.Generator) -> str:
    """Apply primitive operations in order."""
    for op in ops:
        text = PRIMITIVES[op](text, rng)
    return text
