"""ICR-Drive aggregation of stored episodes: means, paired deltas, RD/TO split, bootstrap CIs,
tests and decision statistics.

Pure (numpy and scipy's Wilcoxon test): the same records, in any order, give the same summary bytes.

Definitions (per agent and family f; crashed episodes are counted and excluded from every mean):

- the pairing unit is a route r (with its seed); a *complete pair* (r, k) is a finished variant
  episode of f whose route's baseline episode finished too. Every number of a family is
  computed on its complete pairs alone, so means, deltas, intervals, p-values and flips cover
  the same episodes: ``n`` counts them, ``n_crashed`` the family's crashed episodes and
  ``unpaired`` its finished episodes whose baseline crashed (left out);
- DS, RC, IS: plain means over the complete pairs' variant episodes; base_DS, base_RC,
  base_IS: the means of their baseline episodes (one per pair), so dM = M - base_M;
- dM = mean over all complete pairs (r, k) of M(r, f, k) - M(r, baseline);
- worst_dDS = mean over routes of min over k of dDS_{f,k}(r);
- dDS_ci95 / dRC_ci95: paired bootstrap 95 % percentile interval that resamples routes with
  replacement, each route contributing its mean delta over k (``numpy.random.default_rng``
  seeded with ``boot_seed`` afresh for every agent and family, so one family's interval does
  not depend on which other agents or families are in the records);
- RD, TO: fraction of the complete pairs' variant episodes whose termination class is RD / TO;
- baseline_done_variant_failed: routes whose baseline terminated "done" while at least one
  (non-crashed) variant of the family did not;
- pdr_DS / pdr_RC: the relative drop 1 - M_variant / M_baseline, both means over the family's
  paired episodes (each variant episode against its route's baseline); None when the baseline
  mean is 0;
- p_value: a two-sided Wilcoxon signed-rank test (``scipy.stats.wilcoxon``, zero differences
  dropped) of the per-route mean dDS against 0, Holm-Bonferroni-corrected over the families
  of the agent (``p_value_raw``: uncorrected); 1.0 when every route's dDS is 0;
- flips: {"lost": pairs (route, k) whose baseline terminated "done" and whose variant did
  not, "gained": the reverse};
- model_calls, invalid_answers, invalid_rate (only for an agent that asked a language model,
  :mod:`icrsumo.agents.llm`): its questions over the complete pairs' variant episodes (the
  baseline row: over its episodes), the invalid answers among them, and their share;
- asks, asks_answered, ask_rate, asks_per_episode, answered_rate (only when some episode of the
  run asked for clarification, :mod:`icrsumo.sim.asking`; then on every row): over the same
  episodes, the asks and the answered ones in all, the share of the episodes with at least one
  ask, the mean asks per episode, and the share of the asks that were answered;
- decisions, adherence, confusion, compliance (families only) and, for a language-model agent,
  answers: the decision statistics of :func:`icrsumo.results.attribution.block_stats` over the row's
  episodes (when :func:`summarize` is given the episodes' decisions);
- conditioning_gain (per agent, only when the run has the ``blank`` family): what the
  instruction is worth against none, baseline − blank on the blank family's complete pairs:
  the blank row's dDS, dRC, dIS with the sign turned and its dDS / dRC intervals mirrored
  ([lo, hi] -> [-hi, -lo]: the same resampled routes and seed, so the interval is the bootstrap
  of baseline − blank); ``n`` pairs on ``n_routes`` routes.

:func:`summarize` returns a typed :class:`icrsumo.results.summary.Summary` (summary.json). Values are
rounded (4 decimals, IS and dIS 6); a quantity without data is ``None``, never NaN.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from icrsumo.core.types import EpisodeRecord
from icrsumo.core.vocab import FAMILIES, Family

from .attribution import Key, answer_confusion, block_stats, episode_key
from .summary import (
    AgentStats,
    AnswerCounts,
    AskCounts,
    BaselineStats,
    ConditioningGain,
    DecisionStats,
    EpisodeCounts,
    FamilyStats,
    Flips,
    Interval,
    Summary,
)

if TYPE_CHECKING:
    from .decisions import Decision

BASELINE = Family.BASELINE
BLANK = Family.BLANK

_Key = tuple[str, int]  # (route_id, seed): the pairing unit


def _key(r: EpisodeRecord) -> tuple:
    return (r.agent, r.route_id, r.family, r.k, r.seed)


def _sorted_unique(records: Iterable[EpisodeRecord]) -> list[EpisodeRecord]:
    out = sorted(records, key=_key)
    for a, b in zip(out, out[1:]):
        if _key(a) == _key(b):
            raise ValueError(f"duplicate episode record {_key(a)}")
    return out


def _rnd(x: float | None, nd: int = 4) -> float | None:
    if x is None:
        return None
    x = float(x)
    if not np.isfinite(x):
        return None
    return round(x, nd) + 0.0  # + 0.0 turns -0.0 into 0.0


def _mean(values: Sequence[float], nd: int = 4) -> float | None:
    return _rnd(float(np.mean(values)), nd) if len(values) else None


def _share(recs: Sequence[EpisodeRecord], cls: str) -> float | None:
    if not recs:
        return None
    return _rnd(sum(r.termination_class == cls for r in recs) / len(recs))


def _absolute(recs: Sequence[EpisodeRecord]) -> tuple[float | None, ...]:
    """DS, RC, IS means and the RD, TO shares of ``recs``."""
    return (_mean([r.ds for r in recs]), _mean([r.rc for r in recs]), _mean([r.is_ for r in recs], 6),
            _share(recs, "RD"), _share(recs, "TO"))


def bootstrap_ci(route_means: np.ndarray, *, n_boot: int, seed: int,
                 level: float = 0.95) -> np.ndarray | None:
    """Percentile bootstrap interval(s) of the mean over routes.

    ``route_means`` is (R,) or (R, M) (one column per metric; all columns share the resampled
    route indices). Returns (2,) or (2, M) [lo, hi], or None when R = 0.
    """
    vals = np.asarray(route_means, dtype=float)
    n = vals.shape[0]
    if n == 0:
        return None
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, n, size=(n_boot, n))
    boots = vals[idx].mean(axis=1)  # (n_boot,) or (n_boot, M)
    alpha = (1.0 - level) / 2.0
    return np.percentile(boots, [100.0 * alpha, 100.0 * (1.0 - alpha)], axis=0)


def _answers(recs: Sequence[EpisodeRecord]) -> AnswerCounts:
    """Model calls, invalid answers and their share over ``recs``."""
    calls = sum(r.model_calls for r in recs)
    bad = sum(r.invalid_answers for r in recs)
    return AnswerCounts(calls, bad, _rnd(bad / calls) if calls else None)


def _asks(recs: Sequence[EpisodeRecord]) -> AskCounts:
    """The asks for clarification over ``recs`` (:class:`AskCounts`)."""
    asks = sum(r.asks for r in recs)
    answered = sum(r.asks_answered for r in recs)
    return AskCounts(asks, answered, _mean([r.asks > 0 for r in recs]), _mean([r.asks for r in recs]),
                     _rnd(answered / asks) if asks else None)


@dataclass(frozen=True)
class _Pairs:
    """One agent's complete pairs of one family: the family's finished episodes (``finished``),
    those whose route's baseline finished (``paired``) with that baseline (``pair_base``), and
    per route (sorted) the (dDS, dRC, dIS) of its pairs in k order (``deltas``)."""

    finished: int
    paired: list[EpisodeRecord]
    pair_base: list[EpisodeRecord]
    deltas: list[np.ndarray]
    lost: int
    gained: int
    failed_routes: int

    @classmethod
    def of(cls, recs: list[EpisodeRecord], base: dict[_Key, EpisodeRecord]) -> _Pairs:
        paired = [r for r in recs if (r.route_id, r.seed) in base]
        pair_base = [base[(r.route_id, r.seed)] for r in paired]  # one baseline per pair
        per_route: dict[_Key, list[tuple[float, float, float]]] = {}
        failed: set[_Key] = set()
        lost = gained = 0
        for r, b in zip(paired, pair_base):  # sorted, so per-route lists are in k order
            per_route.setdefault((r.route_id, r.seed), []).append((r.ds - b.ds, r.rc - b.rc, r.is_ - b.is_))
            if b.termination_class == "done" and r.termination_class != "done":
                failed.add((r.route_id, r.seed))
                lost += 1
            elif b.termination_class != "done" and r.termination_class == "done":
                gained += 1
        deltas = [np.asarray(per_route[k], dtype=float) for k in sorted(per_route)]
        return cls(len(recs), paired, pair_base, deltas, lost, gained, len(failed))

    @property
    def route_means(self) -> np.ndarray:
        """(R, 2): per route the mean dDS and dRC over its pairs."""
        return np.stack([d[:, :2].mean(axis=0) for d in self.deltas])

    @property
    def p_value_raw(self) -> float | None:
        """The Wilcoxon p-value of the per-route mean dDS (None without a pair)."""
        return _rnd(paired_test(self.route_means[:, 0]), 6) if self.deltas else None


def _deltas(p: _Pairs, n_boot: int, boot_seed: int) -> dict[str, Any]:
    """The paired deltas of ``p``: mean, worst, bootstrap intervals, relative drops (None each
    without a pair)."""
    if not p.deltas:
        return dict(d_ds=None, d_rc=None, d_is=None, worst_d_ds=None, d_ds_ci95=None, d_rc_ci95=None,
                    pdr_ds=None, pdr_rc=None)
    d_mean = np.concatenate(p.deltas, axis=0).mean(axis=0)  # over the pairs: dDS, dRC, dIS
    worst = float(np.mean([d[:, 0].min() for d in p.deltas]))
    ci = bootstrap_ci(p.route_means, n_boot=n_boot, seed=boot_seed)
    base_mean = np.asarray([(b.ds, b.rc) for b in p.pair_base], dtype=float).mean(axis=0)  # (DS, RC)
    return dict(d_ds=_rnd(d_mean[0]), d_rc=_rnd(d_mean[1]), d_is=_rnd(d_mean[2], 6), worst_d_ds=_rnd(worst),
                d_ds_ci95=(_rnd(ci[0, 0]), _rnd(ci[1, 0])), d_rc_ci95=(_rnd(ci[0, 1]), _rnd(ci[1, 1])),
                pdr_ds=relative_drop(base_mean[0], d_mean[0]), pdr_rc=relative_drop(base_mean[1], d_mean[1]))


def _family_stats(p: _Pairs, *, p_value: float | None, n_boot: int, boot_seed: int, n_crashed: int,
                  answers: bool, asking: bool, decisions: DecisionStats | None,
                  skipped_routes: int = 0) -> FamilyStats:
    ds, rc, is_, rd, to = _absolute(p.paired)
    return FamilyStats(
        ds=ds, rc=rc, is_=is_, base_ds=_mean([b.ds for b in p.pair_base]),
        base_rc=_mean([b.rc for b in p.pair_base]), base_is=_mean([b.is_ for b in p.pair_base], 6),
        **_deltas(p, n_boot, boot_seed), p_value_raw=p.p_value_raw, rd=rd, to=to, n=len(p.paired),
        n_routes=len(p.deltas), baseline_done_variant_failed=p.failed_routes,
        n_pairs=int(sum(len(d) for d in p.deltas)), n_crashed=int(n_crashed),
        unpaired=p.finished - len(p.paired), flips=Flips(p.lost, p.gained), p_value=p_value,
        answers=_answers(p.paired) if answers else None, decisions=decisions,
        asking=_asks(p.paired) if asking else None, skipped_routes=int(skipped_routes))


def _turned(x: float | None) -> float | None:
    return None if x is None else 0.0 - x  # exact, and 0.0 stays 0.0


def conditioning_gain(blank: FamilyStats) -> ConditioningGain:
    """The conditioning gain (baseline − blank) from an agent's ``blank`` row: its paired deltas
    with the sign turned, its intervals mirrored (None stays None)."""
    def mirrored(ci: Interval | None) -> Interval | None:
        return None if ci is None else (_turned(ci[1]), _turned(ci[0]))

    return ConditioningGain(_turned(blank.d_ds), _turned(blank.d_rc), _turned(blank.d_is),
                            mirrored(blank.d_ds_ci95), mirrored(blank.d_rc_ci95), blank.n, blank.n_routes)


def relative_drop(base_mean: float, delta_mean: float) -> float | None:
    """1 - M_variant / M_baseline from the baseline mean and the mean paired delta (None when
    the baseline mean is 0)."""
    if base_mean == 0:
        return None
    return _rnd(-delta_mean / base_mean)


def paired_test(route_deltas: np.ndarray) -> float:
    """Two-sided p-value of a Wilcoxon signed-rank test of ``route_deltas`` ((R,), one mean
    delta per route) against 0; zero deltas are dropped, and 1.0 when none is left."""
    from scipy.stats import wilcoxon

    d = np.asarray(route_deltas, dtype=float)
    d = d[d != 0.0]
    if len(d) == 0:
        return 1.0
    return float(wilcoxon(d, zero_method="wilcox", alternative="two-sided").pvalue)


def holm(p_values: Sequence[float | None]) -> list[float | None]:
    """Holm-Bonferroni adjusted p-values (None stays None): the i-th smallest of m p-values is
    multiplied by m - i (i from 0), then made monotone and capped at 1."""
    known = sorted((p, i) for i, p in enumerate(p_values) if p is not None)
    m = len(known)
    out: list[float | None] = [None] * len(p_values)
    running = 0.0
    for rank, (p, i) in enumerate(known):
        running = max(running, min(1.0, (m - rank) * p))
        out[i] = running
    return out


@dataclass(frozen=True)
class _Attribution:
    """What the decision statistics of a row are computed from: key -> the decisions of each
    finished episode and, for a language-model agent, key -> its (instructed intent, answered
    maneuver) pairs (None: no answers' confusion)."""

    decisions: Mapping[Key, Sequence[Decision]]
    answers: Mapping[Key, Sequence[tuple[Any, Any]]] | None

    def stats(self, recs: Sequence[EpisodeRecord], family: bool, asked: bool) -> DecisionStats:
        """The decision statistics of ``recs`` (one agent's episodes of one family); compliance
        for a variant family alone, the answers' confusion for an agent that asked a model."""
        st = block_stats(self.decisions[k] for r in recs if (k := episode_key(r)) in self.decisions)
        answers = None
        if asked and self.answers is not None:
            answers = answer_confusion(self.answers[k] for r in recs if (k := episode_key(r)) in self.answers)
        return replace(st, compliance=st.compliance if family else None, answers=answers)


def _agent_stats(recs: list[EpisodeRecord], fams: tuple[str, ...], n_boot: int, boot_seed: int,
                 attribution: _Attribution | None, asking: bool = False,
                 skipped: Mapping[str, int] | None = None) -> AgentStats:
    """One agent's rows from its records ``recs`` (crashed ones included); ``asking``: every
    row counts its asks for clarification; ``skipped``: family -> routes it was not built for."""
    crashed = Counter(r.family for r in recs if r.status == "crashed")
    mine = [r for r in recs if r.status != "crashed"]
    base_recs = [r for r in mine if r.family == BASELINE]
    base = {(r.route_id, r.seed): r for r in base_recs if r.k == 0}
    asked = any(r.model_calls for r in mine)

    def decisions(family: str) -> DecisionStats | None:
        if attribution is None:
            return None
        return attribution.stats([r for r in recs if r.family == family], family != BASELINE, asked)

    pairs = {f: _Pairs.of([r for r in mine if r.family == f], base) for f in fams}
    adjusted = holm([pairs[f].p_value_raw for f in fams])
    families = {f: _family_stats(pairs[f], p_value=_rnd(p, 6), n_boot=n_boot, boot_seed=boot_seed,
                                 n_crashed=crashed[f], answers=asked, asking=asking, decisions=decisions(f),
                                 skipped_routes=(skipped or {}).get(f, 0))
                for f, p in zip(fams, adjusted)}
    ds, rc, is_, rd, to = _absolute(base_recs)
    baseline = BaselineStats(ds, rc, is_, rd, to, len(base_recs), crashed[BASELINE],
                             _answers(base_recs) if asked else None, decisions(BASELINE),
                             _asks(base_recs) if asking else None)
    return AgentStats(baseline, families, conditioning_gain(families[BLANK]) if BLANK in families else None)


def summarize(records: Iterable[EpisodeRecord], *, suite: str, seed: int, k: int,
              families: Sequence[str] = FAMILIES, n_boot: int = 2000, boot_seed: int = 2026,
              scoring: str | None = None, digest: str | None = None,
              decisions: Mapping[Key, Sequence[Decision]] | None = None,
              answers: Mapping[Key, Sequence[tuple[Any, Any]]] | None = None,
              rescored_short: int = 0, not_in_report: int = 0, not_in_report_why: str = "",
              skipped_routes: Mapping[str, int] | None = None) -> Summary:
    """ICR-Drive summary of an evaluation (see the module docstring for the definitions).

    Only baseline records and records of ``families`` are considered; agents are listed in
    sorted order, families in the given order. ``n_routes`` is the number of routes that
    contribute paired deltas, ``n_pairs`` (extra) the number of (route, k) pairs.
    ``scoring`` and ``digest``: the rules the records are scored by and the run's digest
    (written together; None: neither). ``decisions`` (key -> the decisions of a finished
    episode, :func:`icrsumo.results.attribution.episode_key`): every row gets its decision statistics
    (None: none does); ``answers``: a language-model agent's (intent, maneuver) pairs by key
    for its rows' answers' confusion. ``rescored_short``, ``not_in_report`` and its
    ``not_in_report_why``: counted in :class:`icrsumo.results.summary.EpisodeCounts`.
    ``skipped_routes``: family -> how many of the evaluation's routes it could not be built for
    (every agent's row of that family carries it).
    """
    fams = tuple(families)
    if BASELINE in fams:
        raise ValueError("families must not include 'baseline'")
    recs = [r for r in _sorted_unique(records) if r.family == BASELINE or r.family in fams]
    n_crashed = sum(r.status == "crashed" for r in recs)
    attribution = None if decisions is None else _Attribution(decisions, answers)
    asking = any(r.asks for r in recs)
    agents = {agent: _agent_stats([r for r in recs if r.agent == agent], fams, n_boot, boot_seed, attribution,
                                  asking, skipped_routes)
              for agent in sorted({r.agent for r in recs})}
    episodes = EpisodeCounts(len(recs) - n_crashed, n_crashed, rescored_short, not_in_report,
                             not_in_report_why)
    return Summary(str(suite), int(seed), int(k), episodes, agents, fams, int(n_boot), int(boot_seed),
                   scoring, digest)


EPISODE_COLUMNS = ("agent", "route_id", "family", "k", "seed", "status", "ds", "rc", "is",
                   "termination", "termination_class", "n_infractions", "infractions", "length",
                   "duration", "attempts", "message", "outside_lanes_pct", "instructions", "end_t",
                   "end_pos", "end_x", "end_y")
#: the columns of :data:`EPISODE_COLUMNS` that come from an episode's log and instructions
END_COLUMNS = ("instructions", "end_t", "end_pos", "end_x", "end_y")


def episode_table(records: Iterable[EpisodeRecord], ends: dict | None = None) -> list[dict]:
    """One flat row per episode (columns :data:`EPISODE_COLUMNS`), sorted by
    (agent, route_id, family, k, seed). ``infractions`` is ``kind:factor`` joined by ``;``;
    ``outside_lanes_pct``: the route advance made outside the lanes, % of the route's length.
    ``ends``: key -> :data:`END_COLUMNS` values read from the episode's log and instructions
    (``instructions``: the ids of its texts, the templates, ``|``-joined; ``end_t`` s and
    ``end_pos`` m along the route where it ended, ``end_x``/``end_y`` m); empty without."""
    rows = []
    ends = ends or {}
    for r in _sorted_unique(records):
        rows.append({
            "agent": r.agent, "route_id": r.route_id, "family": r.family, "k": r.k, "seed": r.seed,
            "status": r.status, "ds": r.ds, "rc": r.rc, "is": r.is_, "termination": r.termination,
            "termination_class": r.termination_class, "n_infractions": len(r.infractions),
            "infractions": ";".join(f"{kind}:{factor:g}" for kind, factor in r.infractions),
            "length": r.length, "duration": r.duration, "attempts": r.attempts,
            "message": r.message.replace("\r", " ").replace("\n", " "),
            "outside_lanes_pct": round(100.0 * r.outside_m / r.length, 2) if r.status == "done" and r.length
            else None,
            **{c: ends.get(_key(r), {}).get(c) for c in END_COLUMNS},
        })
    return rows
