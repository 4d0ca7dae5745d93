"""Training and held-out measurement of the ``text-learned`` guard (:mod:`.text_guard`).

Training data (:func:`training_data`), all of it shippable and none of it a held-out text:

* negatives: commands (the training bank's phrasings, ``data/train_bank.json``, and the general
  commands of ``data/text_guard_general.json``, slots filled at random), alone and wrapped in the
  benign openings and endings of both written files (politeness, hedges, fillers, the passenger's
  own corrections, landmarks, distances), the written negatives and the benign mentions of the
  police, closures, emergencies and the navigation system;
* positives: the misleading bank's templates of the tuning half only (odd template numbers, the
  split of the ``text`` guard: :func:`icrsumo.instructions.banks.template_number`), filled at
  random, their openings before commands, and the general hijacking openings and endings of
  ``data/text_guard_general.json`` (false authority, fake emergencies and closures, "ignore the
  route", overrides, the navigation system impersonated, prompt injection, social engineering)
  around commands;
* each text also twice with the training noise of :func:`icrsumo.learn.augment.add_noise`.

Every text carries a group: the written item it was made from (a template number, an opening,
an ending, a sentence). The head is L2-regularised logistic regression (classes weighted
equally) fitted with L-BFGS; its L2 penalty is the one of :data:`L2_GRID` whose grouped
cross-validation (:data:`FOLDS` folds, whole groups held out, so a fold's openings are never
trained on) detects most positives at a threshold flagging at most :data:`MAX_FALSE_POSITIVES`
of the out-of-fold ordinary negatives (all but the written sentences that mention closures,
authorities, emergencies or the navigation system, whose false blocks are reported apart); the
threshold is that one, from the chosen penalty's out-of-fold scores, and never below 0.5.
Everything is a function of the seed (``numpy.random.Generator``); no held-out text is read.
:func:`heldout_sets` and :func:`written_heldout_sets` give the texts the guard is measured on.
"""

from __future__ import annotations

import json
import zlib
from dataclasses import dataclass
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

#: the first written data (negatives and benign openings)
WRITTEN = Path(__file__).resolve().parent / "data" / "text_guard_data.json"
#: the general written data (hijacking and benign openings and endings, mentions, commands)
GENERAL = Path(__file__).resolve().parent / "data" / "text_guard_general.json"
#: the most out-of-fold training negatives the threshold may flag (half the 1 % target, leaving
#: room for texts unlike the training ones)
MAX_FALSE_POSITIVES = 0.005
#: the L2 penalties cross-validation chooses from (a first run over 1e-6 ... 1e-3 found every
#: penalty from 3e-5 up worse)
L2_GRID = (1e-6, 3e-6, 1e-5, 3e-5)
#: the group prefix of written sentences that mention closures, authorities, emergencies or the
#: navigation system (the threshold's false positives are counted without them)
MENTION = "mention:"

#: cross-validation folds (by group)
FOLDS = 5
#: noised copies per training text
NOISED_COPIES = 2
#: filled copies per training misleading template
POSITIVE_COPIES = 4
#: texts composed of a first-file or bank opening and a command, per class
COMPOSED = 1200
#: texts composed from the general written data, per class
GENERAL_COMPOSED = 4000
#: the distances [x] is filled with in training
DISTANCES = (20, 30, 50, 80, 100, 150, 200, 250, 300, 400, 500)
#: the seed of the held-out noise (fixed: the held-out texts never change)
HELDOUT_SEED = 2026
#: the written held-out set's groups (tests/data/guard_heldout)
WRITTEN_GROUPS = ("misleading", "benign", "benign_mentions")


@dataclass(frozen=True)
class TrainingData:
    """Texts to train on with their ``labels`` (1: misleading) and ``groups`` (the written item
    each was made from; noised copies share their text's group)."""

    texts: list[str]
    labels: np.ndarray
    groups: list[str]


def _tuning(template_id: str) -> bool:
    """Whether a misleading template is of the tuning half (odd number; the text guard's split)."""
    n = template_number(template_id)
    return n is not None and n % 2 == 1


def _pick(items: list[str] | tuple, rng: np.random.Generator):
    return items[int(rng.integers(len(items)))]


def _filled(text: str, rng: np.random.Generator, slots: dict[str, list[str]] | None = None) -> str:
    """``text`` with a random junction, direction, side, ordinal and distance (and a random
    value of each of ``slots``)."""
    side = _pick(("left", "right"), rng)
    values = {k: _pick(v, rng) for k, v in sorted((slots or {}).items())}
    out = fill(text, _pick(sorted(JUNCTION_PHRASES), rng), dir=side, side=side, exit=_pick(ORDINALS, rng),
               **values)
    return out.replace("[x]", str(_pick(DISTANCES, rng)))


def _commands(rng: np.random.Generator, general: list[str]) -> list[tuple[str, str]]:
    """(command, group): every training-bank phrasing and general command, four times filled at
    random (slots, junctions, distances)."""
    bank = [t for phrasings in load_train_bank()["types"].values() for t in phrasings]
    out = [(_filled(t, rng), f"cmd:{t}") for t in bank + general for _ in range(4)]
    return sorted(set(out), key=out.index)


def written_data(path: Path = WRITTEN) -> dict[str, list[str]]:
    """The first written data: ``negatives`` and ``benign_prefixes`` (lists of texts)."""
    data = json.loads(path.read_text(encoding="utf-8"))
    return {k: list(data[k]) for k in ("negatives", "benign_prefixes")}


def general_data(path: Path = GENERAL) -> dict:
    """The general written data (module doc; ``data/text_guard_general.json``'s note)."""
    return json.loads(path.read_text(encoding="utf-8"))


def _tuning_entries(banks: Banks) -> list[tuple[str, str]]:
    """(template text, id) of the misleading bank's tuning half."""
    return [(e.text, e.id) for by_kind in banks.misleading.values() for entries in by_kind.values()
            for e in entries if _tuning(e.id)]


def _framing(template: str) -> str:
    """The opening of a misleading template: up to its first colon, else its first comma."""
    for mark in (":", ","):
        head, sep, _ = template.partition(mark)
        if sep:
            return head + sep
    return ""


def _join(opening: str, command: str, ending: str = "") -> str:
    """"OPENING command, ending" (the command's first letter lower-cased after an opening; the
    ending replaces the command's final stop); a part left empty is left out."""
    text = f"{opening} {command[:1].lower()}{command[1:]}" if opening else command
    if ending:
        text = f"{text.rstrip('.!?')}, {ending}"
    return text[:1].upper() + text[1:]


def _composed(openings: list[str], commands: list[tuple[str, str]], rng: np.random.Generator,
              tag: str) -> list[tuple[str, str]]:
    """:data:`COMPOSED` texts "OPENING command", grouped by opening."""
    out = []
    for _ in range(COMPOSED):
        i = int(rng.integers(len(openings)))
        out.append((_join(openings[i], _pick(commands, rng)[0]), f"{tag}:{openings[i]}"))
    return out


def _general(kinds: dict[str, list[str]], endings: list[str], commands: list[tuple[str, str]],
             slots: dict[str, list[str]], rng: np.random.Generator, tag: str) -> list[tuple[str, str]]:
    """:data:`GENERAL_COMPOSED` texts from openings of each kind in turn and endings around
    commands: a quarter with opening and ending, a tenth with the ending alone, the rest with
    the opening alone; grouped by the opening (or the ending, when alone)."""
    names = sorted(kinds)
    out = []
    for n in range(GENERAL_COMPOSED):
        kind = names[n % len(names)]
        i, j, r = int(rng.integers(len(kinds[kind]))), int(rng.integers(len(endings))), rng.random()
        opening = _filled(kinds[kind][i], rng, slots)
        command = _pick(commands, rng)[0]
        if r < 0.1:
            out.append((_join("", command, endings[j]), f"{tag}-end:{j}"))
        else:
            out.append((_join(opening, command, endings[j] if r < 0.35 else ""), f"{tag}:{kind}:{i}"))
    return out


def _with_noise(items: list[tuple[str, str]], rng: np.random.Generator) -> list[tuple[str, str]]:
    return items + [(add_noise(t, rng), g) for t, g in items for _ in range(NOISED_COPIES)]


def training_data(banks: Banks, seed: int, limit: int | None = None) -> TrainingData:
    """The texts to train on (module doc), drawn from ``seed``; ``limit``: at most that many
    clean texts per class (a small set, for tests)."""
    rng = np.random.default_rng(seed)
    written, general = written_data(), general_data()
    commands = _commands(rng, general["commands"])
    entries = _tuning_entries(banks)
    bank_openings = sorted({_framing(t) for t, _ in entries} - {""})
    neg = commands + [(t, f"{MENTION}{t}") for t in written["negatives"] + general["benign_mentions"]]
    neg += _composed(written["benign_prefixes"], commands, rng, "benign-prefix")
    neg += _general(general["benign_openings"], general["benign_suffixes"], commands, {}, rng, "benign")
    pos = [(_filled(t, rng), f"template:{i.rsplit('.', 1)[-1]}") for t, i in entries
           for _ in range(POSITIVE_COPIES)]
    pos += _composed(bank_openings, commands, rng, "bank-opening")
    pos += _general(general["positive_patterns"], general["positive_suffixes"], commands, general["slots"],
                    rng, "hijack")
    order = rng.permutation(len(neg))[:limit], rng.permutation(len(pos))[:limit]
    neg, pos = _with_noise([neg[i] for i in order[0]], rng), _with_noise([pos[i] for i in order[1]], rng)
    return TrainingData([t for t, _ in neg + pos], np.array([0] * len(neg) + [1] * len(pos), dtype=np.int64),
                        [g for _, g in neg + pos])


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


def fit(x, y: np.ndarray, l2: float) -> tuple[np.ndarray, float]:
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


def _scores(x, weights: np.ndarray, bias: float) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-(x @ weights.astype(np.float64) + bias)))


def choose_threshold(scores: np.ndarray, y: np.ndarray, max_fp: float = MAX_FALSE_POSITIVES) -> float:
    """The smallest threshold (``score >= t`` blocks) that flags at most ``max_fp`` of the
    negatives of ``scores``, and at least 0.5."""
    neg = np.sort(scores[y == 0])[::-1]
    allowed = int(np.floor(max_fp * len(neg)))
    t = float(np.nextafter(neg[allowed], 1.0)) if allowed < len(neg) else 0.0
    return min(max(t, 0.5), float(np.nextafter(1.0, 0.0)))


def folds(groups: list[str], k: int = FOLDS) -> np.ndarray:
    """Each text's fold: its group's CRC-32 modulo ``k`` (a group never spans two folds)."""
    return np.array([zlib.crc32(g.encode("utf-8")) % k for g in groups], dtype=np.int64)


@dataclass(frozen=True)
class CrossValidation:
    """Grouped cross-validation of one L2 penalty: the out-of-fold ``scores``, the ``threshold``
    they give (:func:`choose_threshold`) and the share of positives it flags (``detection``)."""

    l2: float
    scores: np.ndarray
    threshold: float
    detection: float


def cross_validate(x, y: np.ndarray, groups: list[str], l2: float) -> CrossValidation:
    """Out-of-fold scores of :func:`fit` with ``l2``, each fold (:func:`folds`) scored by a
    model fitted on the others; the threshold from the positives and the ordinary negatives."""
    fold, scores = folds(groups), np.zeros(len(y))
    for f in np.unique(fold):
        held = fold == f
        weights, bias = fit(x[~held], y[~held], l2)
        scores[held] = _scores(x[held], weights, bias)
    counted = np.array([not g.startswith(MENTION) for g in groups])
    t = choose_threshold(scores[counted], y[counted])
    return CrossValidation(l2, scores, t, float(np.mean(scores[y == 1] >= t)))


def select(x, y: np.ndarray, groups: list[str], grid: tuple[float, ...] = L2_GRID) -> list[CrossValidation]:
    """:func:`cross_validate` for each penalty of ``grid``, the chosen one first: the highest
    detection, ties to the larger penalty."""
    runs = [cross_validate(x, y, groups, l2) for l2 in grid]
    return sorted(runs, key=lambda r: (-r.detection, -r.l2))


def train(banks: Banks, seed: int, limit: int | None = None,
          grid: tuple[float, ...] = L2_GRID) -> tuple[TextGuardModel, list[CrossValidation]]:
    """The model trained from ``seed`` with the penalty and threshold :func:`select` chooses,
    and the cross-validation runs (chosen first)."""
    data = training_data(banks, seed, limit)
    x = feature_matrix(data.texts)
    runs = select(x, data.labels, data.groups, grid)
    weights, bias = fit(x, data.labels, runs[0].l2)
    return TextGuardModel(weights, bias, runs[0].threshold, seed, runs[0].l2), runs


def heldout_sets(banks: Banks) -> dict[str, list[str]]:
    """The measurement texts of the banks, none trained on: the misleading templates of the
    held-out half (even numbers) and of the tuning half, filled as
    :func:`icrsumo.results.guards.text_holdout` fills them ("the intersection", 100 m), the
    held-out ones under each operation of the noise bank; the evaluation banks' baseline
    instructions (every phrasing and slot value), the paraphrase bank, the baseline instructions
    under each noise operation, and the ambiguity bank."""
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


def written_heldout_sets(path: Path, by_kind: bool = False) -> dict[str, list[str]]:
    """The texts of a written held-out file (``tests/data/guard_heldout/heldout.json``: per group
    of :data:`WRITTEN_GROUPS`, texts by kind), one set per group, "written_GROUP" (``by_kind``:
    one per group and kind, "written_GROUP/KIND")."""
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    if by_kind:
        return {f"written_{g}/{k}": list(v) for g in WRITTEN_GROUPS for k, v in data[g].items()}
    return {f"written_{g}": [t for kind in data[g].values() for t in kind] for g in WRITTEN_GROUPS}


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
