"""Step 1 of the intent classifier: the canonical token stream of an instruction.

Lower-casing, ``[x]`` -> ``<num>``, ordinals spelled out, contractions expanded, clause
boundaries as ``,`` / ``.``, and spelling correction (edit distance within a budget, direction
slots, glued words); :mod:`icrsumo.instructions.intent` documents each rule. The word lists live in
:mod:`icrsumo.instructions.lexicon`.
"""

from __future__ import annotations

import re
from functools import lru_cache

from . import lexicon as lex

__all__ = ["tokens"]

_PLACEHOLDER_RE = re.compile(r"\[\s*x\s*\]")
# Spaced-out letters ("l e f t") first, then words, numbers, the placeholder and punctuation.
_TOKEN_RE = re.compile(
    r"[a-z](?: [a-z]){2,}\b|[a-z]+(?:'[a-z]+)*|\d+(?:[.,]\d+)*[a-z]*|<num>|[.!?;]+|[,:()\u2013\u2014]"
    r"|(?<=\s)-+(?=\s)|--"
)
_ORDINAL_RE = re.compile(r"(\d+)(?:st|nd|rd|th)")
_ORDINAL_NAMES = {v: k for k, v in lex.ORDINALS.items()}
_REPEAT_RE = re.compile(r"([a-z])\1{2,}")
#: the distinct letters of each correction target
_LETTERS = {kw: frozenset(kw) for kw in lex.FUZZY_TARGETS}



def _budget(length: int) -> int:
    """Edit budget for ``length`` letters."""
    return 0 if length <= 2 else 1 if length <= 5 else 2


def _osa(a: str, b: str, limit: int) -> int:
    """Optimal-string-alignment distance of ``a`` and ``b``; ``limit + 1`` once above ``limit``."""
    la, lb = len(a), len(b)
    if abs(la - lb) > limit:
        return limit + 1
    before: list[int] = []
    prev = list(range(lb + 1))
    for i in range(1, la + 1):
        ai = a[i - 1]
        cur = [i] + [0] * lb
        row_min = i
        for j in range(1, lb + 1):
            v = min(prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (ai != b[j - 1]))
            if i > 1 and j > 1 and ai == b[j - 2] and a[i - 2] == b[j - 1] and before[j - 2] + 1 < v:
                v = before[j - 2] + 1
            cur[j] = v
            row_min = min(row_min, v)
        if row_min > limit:
            return limit + 1
        before, prev = prev, cur
    return min(prev[lb], limit + 1)


def _expand_apostrophe(word: str) -> tuple[str, ...]:
    """``don't`` -> do not, ``it's`` -> it is, ``driver's`` -> driver."""
    if word.endswith("n't"):
        stem = word[:-3]
        return (lex.CONTRACTION_STEM.get(stem, stem), "not")
    for tail, full in lex.CONTRACTION_TAIL.items():
        if word.endswith(tail):
            return (word[: -len(tail)], full)
    if word.endswith("'s"):
        stem = word[:-2]
        if stem == "let":
            return ("let", "us")
        return (stem, "is") if stem in lex.IS_PRONOUNS else (stem,)
    return (word.replace("'", ""),)


def _fuzzy(word: str) -> str | None:
    """The closest keyword within its edit budget, or None ("pight" -> light, "rigjt" -> right)."""
    best, best_key = None, (99, True, True)
    n = len(word)
    letters = frozenset(word)
    for kw in lex.FUZZY_TARGETS:
        limit = min(_budget(len(kw)), _budget(n + 1))
        if abs(len(kw) - n) > limit:
            continue
        kw_letters = _LETTERS[kw]
        if len(kw_letters - letters) > limit or len(letters - kw_letters) > limit:
            continue  # each edit adds or removes at most one distinct letter: too far, cheaply
        d = _osa(word, kw, limit)
        if d <= limit:
            # ties: a keyboard-neighbour slip, then the same first letter, then list order
            key = (d, not _neighbour_slip(word, kw), kw[0] != word[0])
            if key < best_key:
                best, best_key = kw, key
    return best


def _neighbour_slip(word: str, kw: str) -> bool:
    """Whether ``word`` is ``kw`` with one letter replaced by a QWERTY neighbour ("wxit")."""
    if len(word) != len(kw):
        return False
    diff = [(a, b) for a, b in zip(word, kw) if a != b]
    return len(diff) == 1 and diff[0][0] in lex.QWERTY_NEIGHBOURS.get(diff[0][1], "")


def _split_glued(word: str) -> tuple[str, str] | None:
    """``turnleft`` -> (turn, left): both halves known and one of them a keyword."""
    for k in range(2, len(word) - 1):
        a, b = word[:k], word[k:]
        if a in lex.KNOWN and b in lex.KNOWN and (a in lex.HEADS or b in lex.HEADS or a in lex.DIRECTIVE):
            return a, b
    return None


@lru_cache(maxsize=65536)
def _correct(word: str) -> tuple[str, ...]:
    """Canonical token(s) for one raw word."""
    if "'" in word:
        out: tuple[str, ...] = ()
        for part in _expand_apostrophe(word):
            out += _correct(part) if part else ()
        return out
    if word in lex.ALIASES:
        return lex.ALIASES[word]
    if _REPEAT_RE.search(word):
        return _correct(_REPEAT_RE.sub(r"\1\1", word))
    if word in lex.KNOWN or len(word) < 3 or not word.isalpha():
        return (word,)
    fixed = _fuzzy(word)
    if fixed is not None:
        return (fixed,)
    return _split_glued(word) or (word,)


@lru_cache(maxsize=65536)
def _slot_direction(word: str) -> str | None:
    """left/right for a typo in a direction slot, else None: one edit ("turn dight"), or two
    edits keeping the first letter or the letters ("turn rgith")."""
    for kw in ("left", "right"):
        d = _osa(word, kw, 2)
        if d <= 1 or (d == 2 and (word[0] == kw[0] or sorted(word) == sorted(kw))):
            return kw
    return None


def _direction_slot(out: list[str], i: int) -> bool:
    """Whether token ``i`` sits where a direction is expected ("turn _", "take a _", "_ lane")."""
    prev = out[i - 1] if i else ""
    if prev in lex.SLOT_PREV or (prev == "a" and i >= 2 and out[i - 2] in ("take", "make", "hang")):
        return True
    return i + 1 < len(out) and out[i + 1] in ("lane", "lanes", "turn")


def _raw_words(text: str) -> list[str]:
    """Regex tokens of ``text``, lower-cased, with ``[x]`` replaced by ``<num>``."""
    text = text.lower().replace("\u2019", "'").replace("\u2018", "'").replace("`", "'")
    if "[" in text:
        text = _PLACEHOLDER_RE.sub(" <num> ", text)
    return _TOKEN_RE.findall(text)


@lru_cache(maxsize=65536)
def _canonical(raw: str) -> tuple[str, ...]:
    """Canonical token(s) of one regex token (boundary, number, ordinal or word)."""
    if raw[0] in ".!?;":
        return (".",)
    if not raw[0].isalnum() and raw != "<num>":
        return (",",)
    if raw[0].isdigit():
        m = _ORDINAL_RE.fullmatch(raw)
        return (_ORDINAL_NAMES.get(int(m.group(1)), "<ord>") if m else raw,)
    return _correct(raw.replace(" ", ""))  # "l e f t" -> left


def _fix_slot(out: list[str], i: int, raw: str) -> str:
    """Token ``i`` (typed as ``raw``) after the second pass: typos and homophones in a direction
    slot ("turn rgith", "turn rite", "turn dight" which alone would read as light)."""
    tok = out[i]
    if tok in lex.SLOT_HOMOPHONES and _direction_slot(out, i):
        return lex.SLOT_HOMOPHONES[tok]
    typo = raw if tok != raw and tok not in lex.LEFT_RIGHT else tok
    if typo not in lex.KNOWN and len(typo) >= 3 and typo.isalpha() and _direction_slot(out, i):
        return _slot_direction(typo) or tok
    return tok


def _join_round_about(out: list[str]) -> list[str]:
    """Join "the round about" into "the roundabout"."""
    if "about" not in out:
        return out
    joined: list[str] = []
    for tok in out:
        if tok == "about" and len(joined) >= 2 and joined[-1] == "round" and joined[-2] in lex.DETS:
            joined[-1] = "roundabout"
        else:
            joined.append(tok)
    return joined


def _typed(raw_words: list[str]) -> list[tuple[str, str]]:
    """(canonical token, word as typed) pairs; a word expanded into several tokens types itself."""
    pairs: list[tuple[str, str]] = []
    for raw in raw_words:
        toks = _canonical(raw)
        pairs.extend((tok, raw if len(toks) == 1 else tok) for tok in toks)
    return pairs


def tokens(text: str) -> tuple[str, ...]:
    """Canonical tokens of ``text`` (see :func:`icrsumo.instructions.intent.normalize`)."""
    pairs = _typed(_raw_words(text))
    out = [tok for tok, _ in pairs]
    fixed = [
        t if t == r and (t in lex.NO_SLOT_FIX or not t.isalpha()) else _fix_slot(out, i, r)
        for i, (t, r) in enumerate(pairs)
    ]
    return tuple(_join_round_about(_slow_down(fixed)))


def _slow_down(out: list[str]) -> list[str]:
    """An unknown word one edit from "slow" before "down" is "slow" ("slwo down")."""
    if "down" not in out:
        return out
    return ["slow" if k + 1 < len(out) and out[k + 1] == "down" and t not in lex.KNOWN and t.isalpha()
            and _osa(t, "slow", 1) <= 1 else t for k, t in enumerate(out)]
