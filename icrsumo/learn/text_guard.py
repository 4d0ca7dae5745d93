"""The ``text-learned`` guard: a linear classifier "misleading or not" over the hashed character
n-gram and word features of the ``ngram`` language encoder (:mod:`icrsumo.learn.text`) and the
text's hashed word pairs, decided from the text alone.

Its weights ship as ``data/text_guard.npz`` (plain arrays, read with ``allow_pickle=False``; no
torch): one weight per hash bucket, a bias, the decision threshold, the seed and L2 penalty it
was trained with. A text's features are the counts of its n-gram and word-pair ids (words
lower-cased, so casing does not count), scaled to unit length; its score is the logistic of
their dot product with the weights plus the bias, and it is blocked when the score reaches the
threshold. An empty text passes. How the weights were trained and measured:
:mod:`icrsumo.learn.text_guard_train` and ``tools/train_text_guard.py``.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np

from icrsumo.core.errors import InputError
from icrsumo.core.vocab import Verdict
from icrsumo.guards.base import GuardContext, GuardInfo

from .text import TextEncoder, words

#: the shipped weights
WEIGHTS = Path(__file__).resolve().parent / "data" / "text_guard.npz"
#: the weights file's format
FORMAT = "icrsumo-text-guard/2"
#: hash buckets of the features (the ``ngram`` encoder's; id 0 is padding, never a feature)
BUCKETS = 2 ** 16
#: n-gram ids read per text (longer texts are cut)
LENGTH = 1024
_FIX = "rebuild it with python tools/train_text_guard.py"


@dataclass(frozen=True)
class TextGuardModel:
    """The classifier: ``weights`` (one per bucket, float32), ``bias``, the decision
    ``threshold`` (a score in (0, 1)), the ``seed`` it was trained from and its ``l2`` penalty."""

    weights: np.ndarray
    bias: float
    threshold: float
    seed: int = 0
    l2: float = 0.0

    def score(self, text: str) -> float:
        """The probability that ``text`` is misleading (0 for a text with no word)."""
        ids, values = features(text, len(self.weights))
        if not len(ids):
            return 0.0
        z = float(np.dot(self.weights[ids].astype(np.float64), values)) + self.bias
        return float(1.0 / (1.0 + np.exp(-z)))

    def save(self, path: Path) -> None:
        """Write the model as a compressed ``.npz`` of plain arrays."""
        np.savez_compressed(path, format=np.array(FORMAT), weights=self.weights.astype(np.float32),
                            bias=np.float64(self.bias), threshold=np.float64(self.threshold),
                            seed=np.int64(self.seed), l2=np.float64(self.l2))


def pair_ids(text: str, buckets: int = BUCKETS) -> list[int]:
    """The bucket ids of ``text``'s adjacent word pairs ("<police order>"), hashed as the
    ``ngram`` encoder hashes n-grams (CRC-32; id 0 is padding, never a feature)."""
    w = words(text)
    return [1 + zlib.crc32(f"<{a} {b}>".encode()) % (buckets - 1) for a, b in zip(w, w[1:])][:LENGTH]


def features(text: str, buckets: int = BUCKETS) -> tuple[np.ndarray, np.ndarray]:
    """(bucket ids, values) of ``text``: each n-gram and word-pair id's count, the vector scaled
    to length 1."""
    ids = TextEncoder("ngram", LENGTH, buckets=buckets).encode(text)
    ids = np.concatenate([ids[ids > 0], np.array(pair_ids(text, buckets), dtype=np.int64)])
    ids, counts = np.unique(ids, return_counts=True)
    values = counts.astype(np.float64)
    return ids, values / np.sqrt((values ** 2).sum()) if len(values) else values


def _scalar(data, path: Path, key: str, kind: str) -> float:
    value = data[key]
    if value.shape != () or value.dtype.kind not in kind or not np.isfinite(value):
        raise InputError(path, key, f"is not a finite number (shape {value.shape}, dtype {value.dtype})",
                         _FIX)
    return value.item()


def load_model(path: Path = WEIGHTS) -> TextGuardModel:
    """The model in ``path``; an InputError naming the file (and key) when it is missing,
    unreadable, of another format or of the wrong shape."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            keys = ("format", "weights", "bias", "threshold", "seed", "l2")
            missing = [k for k in keys if k not in data.files]
            if missing:
                raise InputError(path, missing[0], "missing array: not a text guard's weights", _FIX)
            if data["format"].shape != () or str(data["format"]) != FORMAT:
                raise InputError(path, "format", f"is not {FORMAT}", _FIX)
            weights = data["weights"]
            if weights.shape != (BUCKETS,) or weights.dtype != np.float32 or not np.isfinite(weights).all():
                raise InputError(path, "weights", f"shape {weights.shape} {weights.dtype}, expected "
                                 f"({BUCKETS},) finite float32", _FIX)
            bias, threshold = _scalar(data, path, "bias", "f"), _scalar(data, path, "threshold", "f")
            seed, l2 = int(_scalar(data, path, "seed", "iu")), _scalar(data, path, "l2", "f")
    except InputError:
        raise
    except (OSError, ValueError, EOFError) as err:  # missing, not a zip, a pickled array, truncated
        raise InputError(path, "", f"cannot be read as a text guard's weights ({type(err).__name__})",
                         _FIX) from None
    if not 0.0 < threshold < 1.0:
        raise InputError(path, "threshold", f"{threshold} is not in (0, 1)", _FIX)
    return TextGuardModel(weights, bias, threshold, seed, l2)


@cache
def shipped_model() -> TextGuardModel:
    """The shipped model (read once per process)."""
    return load_model(WEIGHTS)


class LearnedTextGuard:
    """``text-learned``: blocks a text the shipped classifier scores at or above its threshold
    (module doc); from the text alone."""

    name = "text-learned"
    needs_plan = False

    def __init__(self, model: TextGuardModel | None = None) -> None:
        self.model = model or shipped_model()

    def reset(self, info: GuardInfo) -> None:  # noqa: ARG002 - nothing per episode
        return None

    def check(self, text: str, context: GuardContext) -> tuple[Verdict, str]:  # noqa: ARG002 - text alone
        if not text.strip():
            return Verdict.PASS, ""
        p = self.model.score(text)
        if p >= self.model.threshold:
            return Verdict.BLOCK, (f"learned classifier: misleading score {p:.3f} >= threshold "
                                   f"{self.model.threshold:.3f}")
        return Verdict.PASS, ""
