"""The typed summary of an evaluation: what ``OUT/summary.json`` holds.

:func:`icrsumo.results.aggregate.summarize` computes a :class:`Summary` (the definitions of its numbers
are in :mod:`icrsumo.results.aggregate`); the writers of :mod:`icrsumo.reporting` read it.
:meth:`Summary.to_json` is summary.json's text, byte for byte; :meth:`Summary.from_json` and
:meth:`Summary.read` read it back (each problem an InputError naming the file and the key path,
``agents.NAME.families.misleading.dDS``).

Fields are the JSON keys in snake case (``DS`` -> ``ds``, ``IS`` -> ``is_``, ``dDS_ci95`` ->
``d_ds_ci95``, ``worst_dDS`` -> ``worst_d_ds``). A quantity without data is None (JSON null). The
optional parts are None where the JSON has none of their keys: ``answers`` (a language-model
agent's questions), ``decisions`` (the decision statistics of :mod:`icrsumo.results.attribution`),
``scoring`` and ``digest`` (written together), an agent's ``conditioning_gain`` (only when the
run has the ``blank`` family) and ``asking`` (asks for clarification: on every row when some
episode of the run asked).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from icrsumo.core.doccheck import DocChecker
from icrsumo.core.fsio import dumps_json, loads_json, read_json
from icrsumo.core.vocab import Family

#: what a summary.json that cannot be read is fixed with
_FIX = "run icrsumo report on its folder to write it anew"
BASELINE = Family.BASELINE

Counts = Mapping[str, int]
#: instructed intent -> executed branch (or answered maneuver) -> count
Confusion = Mapping[str, Counts]
#: a 95 % interval [lo, hi]
Interval = tuple[float | None, float | None]


@dataclass(frozen=True)
class AnswerCounts:
    """A language-model agent's questions (:mod:`icrsumo.agents.llm`) over a row's episodes, the
    invalid answers among them and their share (None without a question)."""

    model_calls: int
    invalid_answers: int
    invalid_rate: float | None

    def to_dict(self) -> dict[str, Any]:
        return {"model_calls": self.model_calls, "invalid_answers": self.invalid_answers,
                "invalid_rate": self.invalid_rate}


@dataclass(frozen=True)
class AskCounts:
    """Asks for clarification (:mod:`icrsumo.sim.asking`) over a row's episodes: ``asks`` and
    ``asks_answered`` in all, ``ask_rate`` (the share of the episodes with at least one ask),
    ``asks_per_episode`` (their mean) and ``answered_rate`` (the share of the asks the navigator
    answered); a rate is None without an episode, ``answered_rate`` without an ask."""

    asks: int
    asks_answered: int
    ask_rate: float | None
    asks_per_episode: float | None
    answered_rate: float | None

    def to_dict(self) -> dict[str, Any]:
        return {"asks": self.asks, "asks_answered": self.asks_answered, "ask_rate": self.ask_rate,
                "asks_per_episode": self.asks_per_episode, "answered_rate": self.answered_rate}


@dataclass(frozen=True)
class DecisionStats:
    """The decisions of a row's episodes (:func:`icrsumo.results.attribution.block_stats`): outcome ->
    count, ``adherence``, ``confusion``, ``compliance`` (families only: None for the baseline,
    where it is not written) and, for a language-model agent, ``answers`` (instructed intent ->
    answered maneuver -> count; None: not written)."""

    decisions: Counts
    adherence: float | None
    confusion: Confusion
    compliance: float | None = None
    answers: Confusion | None = None

    def to_dict(self, compliance: bool) -> dict[str, Any]:
        out: dict[str, Any] = {"decisions": dict(self.decisions), "adherence": self.adherence,
                               "confusion": _nested(self.confusion)}
        if compliance:
            out["compliance"] = self.compliance
        if self.answers is not None:
            out["answers"] = _nested(self.answers)
        return out


@dataclass(frozen=True)
class BaselineStats:
    """An agent's baseline row: means over its finished baseline episodes, the RD / TO shares,
    ``n`` episodes and ``n_crashed``."""

    ds: float | None
    rc: float | None
    is_: float | None
    rd: float | None
    to: float | None
    n: int
    n_crashed: int
    answers: AnswerCounts | None = None
    decisions: DecisionStats | None = None
    asking: AskCounts | None = None

    def to_dict(self) -> dict[str, Any]:
        return {**_plain(self, _BASELINE_KEYS), **(self.answers.to_dict() if self.answers else {}),
                **(self.asking.to_dict() if self.asking else {}),
                **(self.decisions.to_dict(compliance=False) if self.decisions else {})}


@dataclass(frozen=True)
class Flips:
    """Pairs (route, k) whose baseline completed and whose variant did not (``lost``), and the
    reverse (``gained``)."""

    lost: int
    gained: int


@dataclass(frozen=True)
class ConditioningGain:
    """What the instruction is worth to an agent against none (doScenes' "instruction
    conditioning gain"): baseline − blank, paired on route and seed over the blank family's
    complete pairs, i.e. its row's paired deltas with the sign turned (``ds`` = −dDS, the 95 %
    bootstrap intervals mirrored); ``n`` pairs on ``n_routes`` routes. None without a pair."""

    ds: float | None
    rc: float | None
    is_: float | None
    ds_ci95: Interval | None
    rc_ci95: Interval | None
    n: int
    n_routes: int

    def to_dict(self) -> dict[str, Any]:
        return _plain(self, _GAIN_KEYS)


@dataclass(frozen=True)
class FamilyStats:
    """An agent's row of one family, over its complete pairs (:mod:`icrsumo.results.aggregate` defines
    every number)."""

    ds: float | None
    rc: float | None
    is_: float | None
    base_ds: float | None
    base_rc: float | None
    base_is: float | None
    d_ds: float | None
    d_rc: float | None
    d_is: float | None
    worst_d_ds: float | None
    d_ds_ci95: Interval | None
    d_rc_ci95: Interval | None
    pdr_ds: float | None
    pdr_rc: float | None
    p_value_raw: float | None
    rd: float | None
    to: float | None
    n: int
    n_routes: int
    baseline_done_variant_failed: int
    n_pairs: int
    n_crashed: int
    unpaired: int
    flips: Flips
    p_value: float | None
    answers: AnswerCounts | None = None
    decisions: DecisionStats | None = None
    #: routes of the evaluation the family could not be built for (a delivery family; written
    #: only when not 0)
    skipped_routes: int = 0
    asking: AskCounts | None = None

    def to_dict(self) -> dict[str, Any]:
        return {**_plain(self, _FAMILY_KEYS), "flips": {"lost": self.flips.lost, "gained": self.flips.gained},
                **(self.answers.to_dict() if self.answers else {}),
                **(self.asking.to_dict() if self.asking else {}), "p_value": self.p_value,
                **(self.decisions.to_dict(compliance=True) if self.decisions else {}),
                **({"skipped_routes": self.skipped_routes} if self.skipped_routes else {})}


#: a row of the tables: the baseline's or a family's
Block = BaselineStats | FamilyStats

#: (field, JSON key, kind) of a row's plain values, in summary.json's order; kinds: number (or
#: None), count (an integer >= 0), interval ([lo, hi] or None)
_BASELINE_KEYS = (("ds", "DS", "number"), ("rc", "RC", "number"), ("is_", "IS", "number"),
                  ("rd", "RD", "number"), ("to", "TO", "number"), ("n", "n", "count"),
                  ("n_crashed", "n_crashed", "count"))
_FAMILY_KEYS = (
    ("ds", "DS", "number"), ("rc", "RC", "number"), ("is_", "IS", "number"), ("base_ds", "base_DS", "number"),
    ("base_rc", "base_RC", "number"), ("base_is", "base_IS", "number"), ("d_ds", "dDS", "number"),
    ("d_rc", "dRC", "number"), ("d_is", "dIS", "number"), ("worst_d_ds", "worst_dDS", "number"),
    ("d_ds_ci95", "dDS_ci95", "interval"), ("d_rc_ci95", "dRC_ci95", "interval"),
    ("pdr_ds", "pdr_DS", "number"), ("pdr_rc", "pdr_RC", "number"), ("p_value_raw", "p_value_raw", "number"),
    ("rd", "RD", "number"), ("to", "TO", "number"), ("n", "n", "count"), ("n_routes", "n_routes", "count"),
    ("baseline_done_variant_failed", "baseline_done_variant_failed", "count"),
    ("n_pairs", "n_pairs", "count"), ("n_crashed", "n_crashed", "count"), ("unpaired", "unpaired", "count"))
_GAIN_KEYS = (("ds", "DS", "number"), ("rc", "RC", "number"), ("is_", "IS", "number"),
              ("ds_ci95", "DS_ci95", "interval"), ("rc_ci95", "RC_ci95", "interval"), ("n", "n", "count"),
              ("n_routes", "n_routes", "count"))


@dataclass(frozen=True)
class AgentStats:
    """One agent: its baseline row, one row per family (in the summary's family order) and its
    ``conditioning_gain`` (None when the run has no ``blank`` family; summary.json then has no
    such key)."""

    baseline: BaselineStats
    families: Mapping[str, FamilyStats]
    conditioning_gain: ConditioningGain | None = None

    def blocks(self) -> list[tuple[str, Block]]:
        """(family, row) for the baseline first, then every family."""
        return [(BASELINE, self.baseline), *self.families.items()]

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"baseline": self.baseline.to_dict(),
                               "families": {f: b.to_dict() for f, b in self.families.items()}}
        if self.conditioning_gain is not None:
            out["conditioning_gain"] = self.conditioning_gain.to_dict()
        return out


@dataclass(frozen=True)
class EpisodeCounts:
    """The evaluation's episodes by status; ``rescored_short``: rescored episodes that ended
    before the report's scoring would have ended them; ``stored_not_in_report``: stored episodes
    the tables do not hold, and why (each written only when not 0)."""

    done: int
    crashed: int
    rescored_short: int = 0
    stored_not_in_report: int = 0
    stored_not_in_report_why: str = ""

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"done": self.done, "crashed": self.crashed}
        if self.rescored_short:
            out["rescored_short"] = self.rescored_short
        if self.stored_not_in_report:
            out["stored_not_in_report"] = self.stored_not_in_report
            out["stored_not_in_report_why"] = self.stored_not_in_report_why
        return out


@dataclass(frozen=True)
class Summary:
    """An evaluation's summary (summary.json): the run (suite, seed, k, families, the bootstrap's
    ``n_boot`` and ``boot_seed``, ``scoring`` and the run's ``digest``: None when a damaged log
    leaves the store without one), its episode counts and every agent's rows, agents in sorted
    order."""

    suite: str
    seed: int
    k: int
    episodes: EpisodeCounts
    agents: Mapping[str, AgentStats]
    families: tuple[str, ...]
    n_boot: int
    boot_seed: int
    scoring: str | None = None
    digest: str | None = None

    def rows(self) -> list[tuple[str, str, Block]]:
        """(agent, family, row) for every table row: per agent the baseline first, then each family."""
        return [(agent, fam, b) for agent, a in self.agents.items() for fam, b in a.blocks()]

    @property
    def has_answers(self) -> bool:
        """Whether an agent asked a language model (its rows carry :class:`AnswerCounts`)."""
        return any(a.baseline.answers is not None for a in self.agents.values())

    @property
    def has_asks(self) -> bool:
        """Whether an agent asked for clarification in the run (its rows carry :class:`AskCounts`)."""
        return any(a.baseline.asking is not None for a in self.agents.values())

    @property
    def has_conditioning_gain(self) -> bool:
        """Whether an agent has a :class:`ConditioningGain` (the run has the blank family)."""
        return any(a.conditioning_gain is not None for a in self.agents.values())

    def to_dict(self) -> dict[str, Any]:
        """The JSON document (plain dicts and lists), keys in summary.json's order."""
        out: dict[str, Any] = {
            "suite": self.suite, "seed": self.seed, "k": self.k, "episodes": self.episodes.to_dict(),
            "agents": {name: a.to_dict() for name, a in self.agents.items()}, "families": list(self.families),
            "n_boot": self.n_boot, "boot_seed": self.boot_seed}
        if self.scoring is not None:
            out["scoring"] = self.scoring
            out["digest"] = self.digest
        return out

    def to_json(self) -> str:
        """summary.json's text (:func:`icrsumo.core.fsio.dumps_json` of :meth:`to_dict`)."""
        return dumps_json(self.to_dict())

    @classmethod
    def from_dict(cls, doc: Any, source: object = "summary.json") -> Summary:
        """The summary of a parsed summary.json ``doc``; an InputError names ``source`` (its
        file) and the first key that is missing or of the wrong type."""
        return _Reader(source).summary(doc)

    @classmethod
    def from_json(cls, text: str, source: object = "summary.json") -> Summary:
        """The summary of summary.json's ``text`` (strict JSON); errors name ``source``."""
        return cls.from_dict(loads_json(text, source, "evaluation summary", _FIX), source)

    @classmethod
    def read(cls, path: Path) -> Summary:
        """The summary in the file ``path`` (an out folder's summary.json)."""
        return cls.from_dict(read_json(Path(path), "evaluation summary", _FIX), path)

    def __getitem__(self, key: str) -> Any:
        """Deprecated: summary.json's mapping (``summary["agents"]["A"]["baseline"]["DS"]``), as
        summaries were before they were typed; read the fields (``summary.agents["A"].baseline.ds``)."""
        warnings.warn("Summary[key] is deprecated: read the typed fields (summary.agents[NAME].baseline.ds) "
                      "or summary.to_dict()", DeprecationWarning, stacklevel=2)
        return self.to_dict()[key]


def _nested(table: Confusion) -> dict[str, dict[str, int]]:
    return {k: dict(v) for k, v in table.items()}


def _plain(row: Block | ConditioningGain, keys: tuple[tuple[str, str, str], ...]) -> dict[str, Any]:
    """The plain values of ``row`` by their JSON keys (an interval as a list)."""
    out = {key: getattr(row, name) for name, key, _ in keys}
    return {key: list(v) if isinstance(v, tuple) else v for key, v in out.items()}


class _Reader(DocChecker):
    """Typed reads of a parsed summary.json."""

    def __init__(self, source: object) -> None:
        super().__init__(source, _FIX)

    def opt_number(self, d: dict, key: str, at: str) -> float | None:
        v = self.key(d, key, at)
        return None if v is None else self.number(v, f"{at}.{key}")

    def count(self, d: dict, key: str, at: str) -> int:
        return self.integer(self.key(d, key, at), f"{at}.{key}", lo=0)

    def counts(self, v: Any, at: str) -> dict[str, int]:
        return {k: self.integer(n, f"{at}.{k}", lo=0) for k, n in self.obj(v, at).items()}

    def confusion(self, v: Any, at: str) -> dict[str, dict[str, int]]:
        return {k: self.counts(row, f"{at}.{k}") for k, row in self.obj(v, at).items()}

    def interval(self, d: dict, key: str, at: str) -> Interval | None:
        v, place = self.key(d, key, at), f"{at}.{key}"
        if v is None:
            return None
        if len(self.lst(v, place)) != 2:
            raise self.fail(place, f"holds {len(v)} numbers, not [lo, hi]")
        lo, hi = (None if x is None else self.number(x, f"{place}[{i}]") for i, x in enumerate(v))
        return (lo, hi)

    def answers(self, d: dict, at: str) -> AnswerCounts | None:
        if "model_calls" not in d:
            return None
        return AnswerCounts(self.count(d, "model_calls", at), self.count(d, "invalid_answers", at),
                            self.opt_number(d, "invalid_rate", at))

    def asking(self, d: dict, at: str) -> AskCounts | None:
        if "asks" not in d:
            return None
        return AskCounts(self.count(d, "asks", at), self.count(d, "asks_answered", at),
                         self.opt_number(d, "ask_rate", at), self.opt_number(d, "asks_per_episode", at),
                         self.opt_number(d, "answered_rate", at))

    def decisions(self, d: dict, at: str) -> DecisionStats | None:
        if "decisions" not in d:
            return None
        answers = self.confusion(d["answers"], f"{at}.answers") if "answers" in d else None
        compliance = self.opt_number(d, "compliance", at) if "compliance" in d else None
        return DecisionStats(self.counts(self.key(d, "decisions", at), f"{at}.decisions"),
                             self.opt_number(d, "adherence", at),
                             self.confusion(self.key(d, "confusion", at), f"{at}.confusion"),
                             compliance, answers)

    def plain(self, d: dict, keys: tuple[tuple[str, str, str], ...], at: str) -> dict[str, Any]:
        """Field -> value of a row's plain values (:data:`_FAMILY_KEYS`, :data:`_GAIN_KEYS`)."""
        read = {"number": self.opt_number, "count": self.count, "interval": self.interval}
        return {name: read[kind](d, key, at) for name, key, kind in keys}

    def baseline(self, d: Any, at: str) -> BaselineStats:
        d = self.obj(d, at)
        return BaselineStats(**self.plain(d, _BASELINE_KEYS, at), answers=self.answers(d, at),
                             decisions=self.decisions(d, at), asking=self.asking(d, at))

    def family(self, d: Any, at: str) -> FamilyStats:
        d = self.obj(d, at)
        flips, place = self.obj(self.key(d, "flips", at), f"{at}.flips"), f"{at}.flips"
        return FamilyStats(**self.plain(d, _FAMILY_KEYS, at),
                           flips=Flips(self.count(flips, "lost", place), self.count(flips, "gained", place)),
                           p_value=self.opt_number(d, "p_value", at), answers=self.answers(d, at),
                           decisions=self.decisions(d, at),
                           skipped_routes=self.count(d, "skipped_routes", at) if "skipped_routes" in d else 0,
                           asking=self.asking(d, at))

    def agent(self, d: Any, at: str) -> AgentStats:
        d = self.obj(d, at)
        fams = self.obj(self.key(d, "families", at), f"{at}.families")
        return AgentStats(self.baseline(self.key(d, "baseline", at), f"{at}.baseline"),
                          {f: self.family(b, f"{at}.families.{f}") for f, b in fams.items()},
                          self.gain(d.get("conditioning_gain"), f"{at}.conditioning_gain"))

    def gain(self, v: Any, at: str) -> ConditioningGain | None:
        """An agent's conditioning gain (None: no key, or null)."""
        return None if v is None else ConditioningGain(**self.plain(self.obj(v, at), _GAIN_KEYS, at))

    def episodes(self, d: Any) -> EpisodeCounts:
        d = self.obj(d, "episodes")
        why = self.key(d, "stored_not_in_report_why", "episodes") if "stored_not_in_report" in d else ""
        return EpisodeCounts(self.count(d, "done", "episodes"), self.count(d, "crashed", "episodes"),
                             self.count(d, "rescored_short", "episodes") if "rescored_short" in d else 0,
                             self.count(d, "stored_not_in_report", "episodes") if "stored_not_in_report" in d
                             else 0, self.string(why, "episodes.stored_not_in_report_why"))

    def summary(self, doc: Any) -> Summary:
        """The summary of ``doc``; the keys are read in summary.json's order."""
        d = self.obj(doc, "top level")
        suite = self.string(self.key(d, "suite"), "suite")
        seed = self.integer(self.key(d, "seed"), "seed")
        k = self.integer(self.key(d, "k"), "k", lo=0)
        episodes = self.episodes(self.key(d, "episodes"))
        rows = self.obj(self.key(d, "agents"), "agents")
        agents = {name: self.agent(a, f"agents.{name}") for name, a in rows.items()}
        names = self.lst(self.key(d, "families"), "families")
        fams = tuple(self.string(f, f"families[{i}]") for i, f in enumerate(names))
        n_boot = self.integer(self.key(d, "n_boot"), "n_boot", lo=0)
        boot_seed = self.integer(self.key(d, "boot_seed"), "boot_seed")
        scoring = self.string(d["scoring"], "scoring") if "scoring" in d else None
        digest = None if d.get("digest") is None else self.string(d["digest"], "digest")
        return Summary(suite, seed, k, episodes, agents, fams, n_boot, boot_seed, scoring, digest)
