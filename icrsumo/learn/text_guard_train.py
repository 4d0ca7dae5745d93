"""Training and held-out measurement of the ``text-learned`` guard (:mod:`.text_guard`).

Training data (:func:`training_set`), all of it shippable and none of it from the held-out texts:

* negatives: the training bank's phrasings (``data/train_bank.json``, no text of an evaluation
  bank), slots filled at random, the written negatives of ``data/text_guard_data.json``
  (directions mentioned but not commanded, notices, other road users) and its benign openings
  before training-bank commands;
* positives: the misleading bank's templates of the tuning half only (odd template numbers, the
  split of the ``text`` guard: :func:`icrsumo.instructions.banks.template_number`), filled at
  random, their openings and the written authority framings before training-bank commands;
* each text also twice with the training noise of :func:`icrsumo.learn.augment.add_noise`.

The head is L2-regularised logistic regression (classes weighted equally) fitted with
L-BFGS; the threshold is the smallest score that flags at most :data:`MAX_FALSE_POSITIVES` of
the training negatives, and never below 0.5. Everything is a function of the seed
(``numpy.random.Generator``). :func:`heldout_sets` gives the texts the guard is measured on.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from icrsumo.instructions.banks import (
    JUNCTION_PHRASES,
    ORDINALS,
    Banks,
    baseline_catalogue,
    fill,
    template_number,
)
from icrsumo.instructions.noise import apply_ops

from .augment import add_noise, load_train_bank
from .text_guard import BUCKETS, TextGuardModel, features

#: the written data (negatives, benign openings, authority framings)
WRITTEN = Path(__file__).resolve().parent / "data" / "text_guard_data.json"
#: the most training negatives the threshold may flag
MAX_FALSE_POSITIVES = 0.01
#: L2 penalty of the logistic head
L2 = 1e-5
#: noised copies per training text
NOISED_COPIES = 2
#: filled copies per training misleading template
POSITIVE_COPIES = 4
#: texts composed of an opening and a training-bank command, per class
COMPOSED = 1200
#: the distances [x] is filled with in training
DISTANCES = (20, 30, 50, 80, 100, 150, 200, 250, 300, 400, 500)
#: the seed of the held-out noise (fixed: the held-out texts never change)
HELDOUT_SEED = 2026


def _tuning(template_id: str) -> bool:
    """Whether a misleading template is of the tuning half (odd number; the text guard's split)."""
    n = template_number(template_id)
    return n is not None and n % 2 == 1


def _pick(items: list[str] | tuple, rng: np.random.Generator):
    return items[int(rng.integers(len(items)))]


def _filled(text: str, rng: np.random.Generator) -> str:
    """``text`` with a random junction, direction, side, ordinal and distance."""
    side = _pick(("left", "right"), rng)
    out = fill(text, _pick(sorted(JUNCTION_PHRASES), rng), dir=side, side=side, exit=_pick(ORDINALS, rng))
    return out.replace("[x]", str(_pick(DISTANCES, rng)))


def _commands(rng: np.random.Generator) -> list[str]:
    """Every training-bank phrasing, four times filled at random (slots, junctions, distances)."""
    out = [_filled(t, rng) for phrasings in load_train_bank()["types"].values() for t in phrasings
           for _ in range(4)]
    return sorted(set(out), key=out.index)


def written_data(path: Path = WRITTEN) -> dict[str, list[str]]:
    """The written data: ``negatives``, ``benign_prefixes`` and ``framings`` (lists of texts)."""
    data = json.loads(path.read_text(encoding="utf-8"))
    return {k: list(data[k]) for k in ("negatives", "benign_prefixes", "framings")}


def _tuning_templates(banks: Banks) -> list[str]:
    return [e.text for by_kind in banks.misleading.values() for entries in by_kind.values()
            for e in entries if _tuning(e.id)]


def _framing(template: str) -> str:
    """The opening of a misleading template: up to its first colon, else its first comma."""
    for mark in (":", ","):
        head, sep, _ = template.partition(mark)
        if sep:
            return head + sep
    return ""


def _composed(openings: list[str], commands: list[str], rng: np.random.Generator) -> list[str]:
    """:data:`COMPOSED` texts "OPENING command" (the command's first letter lower-cased)."""
    out = []
    for _ in range(COMPOSED):
        c = _pick(commands, rng)
        out.append(f"{_pick(openings, rng)} {c[:1].lower()}{c[1:]}")
    return out


def _with_noise(texts: list[str], rng: np.random.Generator) -> list[str]:
    return texts + [add_noise(t, rng) for t in texts for _ in range(NOISED_COPIES)]


def training_set(banks: Banks, seed: int, limit: int | None = None,
                 framings: bool = True) -> tuple[list[str], np.ndarray]:
    """(texts, labels: 1 misleading) to train on, drawn from ``seed``; ``limit``: at most that
    many clean texts per class (a small set, for tests); ``framings``: whether the written
    authority framings are used (without them the positives come from the bank's tuning half alone)."""
    rng = np.random.default_rng(seed)
    written, commands, templates = written_data(), _commands(rng), _tuning_templates(banks)
    openings = sorted({_framing(t) for t in templates} - {""}) + (written["framings"] if framings else [])
    neg = commands + written["negatives"] + _composed(written["benign_prefixes"], commands, rng)
    pos = [_filled(t, rng) for t in templates for _ in range(POSITIVE_COPIES)]
    pos += _composed(openings, commands, rng)
    order = rng.permutation(len(neg))[:limit], rng.permutation(len(pos))[:limit]
    neg, pos = _with_noise([neg[i] for i in order[0]], rng), _with_noise([pos[i] for i in order[1]], rng)
    return neg + pos, np.array([0] * len(neg) + [1] * len(pos), dtype=np.int64)


def feature_matrix(texts: list[str], buckets: int = BUCKETS):
    """The (texts, buckets) sparse matrix of :func:`icrsumo.learn.text_guard.features`."""
    from scipy.sparse import csr_matrix

    rows, cols, vals = [], [], []
    for i, t in enumerate(texts):
        ids, v = features(t, buckets)
        rows += [i] * len(ids)
        cols += ids.tolist()
        vals += v.tolist()
    return csr_matrix((vals, (rows, cols)), shape=(len(texts), buckets), dtype=np.float64)


def fit(x, y: np.ndarray, l2: float = L2) -> tuple[np.ndarray, float]:
    """(weights, bias) of the logistic head on features ``x`` and labels ``y`` (L-BFGS, each
    class weighted to half the loss; deterministic)."""
    from scipy.optimize import minimize

    n, d = x.shape
    w_class = np.where(y == 1, 0.5 / max(int(y.sum()), 1), 0.5 / max(int((1 - y).sum()), 1))
    sign = 2.0 * y - 1.0

    def loss(theta: np.ndarray) -> tuple[float, np.ndarray]:
        z = (x @ theta[:d] + theta[d]) * sign
        loss = float(np.sum(w_class * np.logaddexp(0.0, -z))) + 0.5 * l2 * float(theta[:d] @ theta[:d])
        g = -w_class * sign / (1.0 + np.exp(z))
        grad = np.concatenate([x.T @ g + l2 * theta[:d], [g.sum()]])
        return loss, grad

    res = minimize(loss, np.zeros(d + 1), jac=True, method="L-BFGS-B", options={"maxiter": 500})
    return res.x[:d].astype(np.float32), float(res.x[d])


def choose_threshold(scores: np.ndarray, y: np.ndarray, max_fp: float = MAX_FALSE_POSITIVES) -> float:
    """The smallest threshold (``score >= t`` blocks) that flags at most ``max_fp`` of the
    negatives of ``scores``, and at least 0.5."""
    neg = np.sort(scores[y == 0])[::-1]
    allowed = int(np.floor(max_fp * len(neg)))
    t = float(np.nextafter(neg[allowed], 1.0)) if allowed < len(neg) else 0.0
    return min(max(t, 0.5), float(np.nextafter(1.0, 0.0)))


def train(banks: Banks, seed: int, limit: int | None = None, framings: bool = True) -> TextGuardModel:
    """The model trained from ``seed`` (:func:`training_set`, :func:`fit`, :func:`choose_threshold`)."""
    texts, y = training_set(banks, seed, limit, framings)
    x = feature_matrix(texts)
    weights, bias = fit(x, y)
    z = x @ weights.astype(np.float64) + bias
    return TextGuardModel(weights, bias, choose_threshold(1.0 / (1.0 + np.exp(-z)), y), seed)


def heldout_sets(banks: Banks) -> dict[str, list[str]]:
    """The measurement texts, none trained on: the misleading templates of the held-out half
    (even numbers) and of the tuning half, filled as :func:`icrsumo.results.guards.text_holdout`
    fills them ("the intersection", 100 m), the held-out ones under each operation of the noise
    bank; the evaluation banks' baseline instructions (every phrasing and slot value), the
    paraphrase bank, the baseline instructions under each noise operation, and the ambiguity bank."""
    rng = np.random.default_rng(HELDOUT_SEED)

    def filled(text: str) -> str:
        return fill(text, "crossroad").replace("[x]", "100")

    halves: dict[bool, list[str]] = {True: [], False: []}
    for by_kind in banks.misleading.values():
        for entries in by_kind.values():
            for e in entries:
                halves[_tuning(e.id)].append(filled(e.text))
    baseline = [filled(t) for _, t, _ in baseline_catalogue(banks)]
    baseline += [filled(t) for k, v in banks.baseline.items() if k == "start" or k.startswith("notice_")
                 for t in v]
    paraphrase = [filled(e.text) for by_kind in banks.paraphrase.values() for es in by_kind.values()
                  for e in es]

    def noised(texts: list[str]) -> list[str]:
        return [apply_ops(t, ops, rng) for t in texts for _, ops in banks.noise]

    return {"misleading_held_out": halves[False], "misleading_held_out_noised": noised(halves[False]),
            "misleading_tuning": halves[True], "baseline": baseline, "paraphrase": paraphrase,
            "noise": noised(baseline), "ambiguity": [e.text for e in banks.ambiguity]}


def measure(guard, sets: dict[str, list[str]]) -> dict[str, dict[str, float | int]]:
    """Per set of :func:`heldout_sets`: texts, how many ``guard`` blocked and the rate (checked
    with no previous instruction)."""
    from icrsumo.guards.base import GuardContext, verdict_of

    ctx = GuardContext(t=0.0, progress=0.0, instruction_id=0, previous="")
    out = {}
    for name, texts in sets.items():
        blocked = sum(str(verdict_of(guard.check(t, ctx), guard.name)[0]) == "block" for t in texts)
        out[name] = {"texts": len(texts), "blocked": blocked, "rate": round(blocked / len(texts), 4)}
    return out
