"""Text -> the language encoders' inputs (no torch).

* ``token``: lower-cased word tokens (numbers -> ``<num>``) looked up in a vocabulary built
  from the training instructions (baseline phrasings); unseen words -> ``<unk>``.
* ``ngram``: fastText-style hashed features: every word's character 3- to 5-grams with
  boundary marks plus the word itself, hashed (CRC-32) into ``buckets`` ids; no vocabulary, so a
  misspelt or unseen word still shares most of its n-grams with the words it resembles.

* ``minilm``: the (384,) float32 sentence embedding of the pretrained all-MiniLM-L6-v2
  (:mod:`icrsumo.learn.minilm`), frozen; the network learns only what it makes of it.
* ``minilm-tuned``: the token states entering all-MiniLM-L6-v2's last layer, (T, 384) float32
  flattened (T = ``length`` / 384 tokens: longer texts cut, shorter ones zero-padded); the
  network holds its own copy of that layer and fine-tunes it.

``token`` and ``ngram`` give a fixed-length ``(L,)`` int64 array, 0-padded (0 is padding in
both schemes); ``minilm`` a ``(384,)`` and ``minilm-tuned`` a ``(length,)`` float32 array.
"""

from __future__ import annotations

import re
import zlib
from collections.abc import Iterable
from dataclasses import dataclass
from functools import cache

import numpy as np

from .minilm import DIM

PAD, UNK, NUM = "<pad>", "<unk>", "<num>"
_TOKEN = re.compile(r"[a-z]+|\d+")
ENCODERS = ("token", "ngram", "minilm", "minilm-tuned")
#: encoders whose input is a float vector of ``length`` values rather than ids
VECTOR_ENCODERS = ("minilm", "minilm-tuned")
#: values per token of ``minilm-tuned``'s states (the encoder's width)
STATE_WIDTH = DIM


def words(text: str) -> list[str]:
    """Lower-cased word tokens of ``text``, digits as ``<num>``."""
    return [NUM if w.isdigit() else w for w in _TOKEN.findall(text.lower())]


def build_vocab(texts: Iterable[str], min_count: int = 1) -> list[str]:
    """Vocabulary (id -> word) of ``texts``: ``<pad>``, ``<unk>``, then words by falling
    count and alphabetically (deterministic)."""
    counts: dict[str, int] = {}
    for t in texts:
        for w in words(t):
            counts[w] = counts.get(w, 0) + 1
    kept = sorted((w for w, c in counts.items() if c >= min_count), key=lambda w: (-counts[w], w))
    return [PAD, UNK] + [w for w in kept if w not in (PAD, UNK)]


def ngrams(word: str, n_min: int = 3, n_max: int = 5) -> list[str]:
    """The word itself (marked) and its character n-grams with ``<`` ``>`` boundary marks."""
    w = f"<{word}>"
    out = [w]
    for n in range(n_min, n_max + 1):
        out += [w[i:i + n] for i in range(len(w) - n + 1)]
    return out


@dataclass(frozen=True)
class TextEncoder:
    """Maps text to ``(length,)`` int64 ids for the ``kind`` encoder (``token``: ``vocab``;
    ``ngram``: ``buckets`` hash ids, id 0 reserved for padding)."""

    kind: str
    length: int
    vocab: tuple[str, ...] = ()
    buckets: int = 0

    @property
    def dtype(self) -> type:
        """The dtype of :meth:`encode`'s array."""
        return np.float32 if self.kind in VECTOR_ENCODERS else np.int64

    def encode(self, text: str) -> np.ndarray:
        if self.kind == "minilm":
            from .minilm import encoder

            return encoder().embed(text)
        if self.kind == "minilm-tuned":
            from .minilm import encoder

            states = encoder().states(text)[: self.length // STATE_WIDTH]
            vec = np.zeros(self.length, dtype=np.float32)
            vec[: states.size] = states.reshape(-1)
            return vec
        out = np.zeros(self.length, dtype=np.int64)
        if self.kind == "token":
            index = _index(self.vocab)
            ids = [index.get(w, 1) for w in words(text)]
        else:
            ids = [1 + zlib.crc32(g.encode("utf-8")) % (self.buckets - 1)
                   for w in words(text) for g in ngrams(w)]
        ids = ids[: self.length]
        out[: len(ids)] = ids
        return out

    def encode_many(self, texts: list[str]) -> np.ndarray:
        """``(len(texts), length)`` ids (or vectors)."""
        return np.stack([self.encode(t) for t in texts]) if texts else np.zeros((0, self.length), self.dtype)

    @property
    def num_ids(self) -> int:
        """Embedding table size."""
        return len(self.vocab) if self.kind == "token" else self.buckets


@cache
def _index(vocab: tuple[str, ...]) -> dict[str, int]:
    return {w: i for i, w in enumerate(vocab)}
