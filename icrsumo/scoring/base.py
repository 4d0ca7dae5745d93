"""What a scoring rule set provides (:class:`Scoring`): its route criteria (when an episode
ends), its collision counting, the episode's step budget, the per-episode score and the
leaderboard results file. A rule set subclasses :class:`Scoring` in one module
(:mod:`icrsumo.scoring.lb1`, :mod:`icrsumo.scoring.lb2`) and is registered by name
(:mod:`icrsumo.scoring.registry`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable, Mapping, Sequence
from typing import ClassVar

from icrsumo.core.types import EpisodeLog, EpisodeRecord, EpisodeResult, Event, Infraction
from icrsumo.core.vocab import EventKind

from .criteria import RouteRules, TerminationMonitor, cut_at_end, ended_by
from .leaderboard import Logs
from .penalties import PENALTIES, RULE_EVENTS, check_event_kinds, episode_result
from .route import DenseRoute

#: simulated time (s) the step budget allows beyond :meth:`Scoring.time_budget`, and steps
#: beyond that (the monitor ends every episode first; this only bounds the loop)
BUDGET_MARGIN_S = 10.0
BUDGET_MARGIN_STEPS = 10
#: route id -> the route file's key points (its waypoints, m), where known
KeyPoints = Mapping[str, Sequence[Sequence[float]]]


class Scoring(ABC):
    """One scoring rule set. Subclasses set ``name`` (what users pass to ``--scoring``),
    ``title`` (what it reproduces) and ``rules`` (its route criteria, run by the shared
    :class:`~icrsumo.scoring.criteria.TerminationMonitor`), and implement
    :meth:`counted_collisions`, :meth:`time_budget` and :meth:`leaderboard_file`."""

    name: ClassVar[str]
    title: ClassVar[str]
    rules: ClassVar[RouteRules]

    # ------------------------------------------------------------------ what a rule set defines
    @abstractmethod
    def counted_collisions(self, log: EpisodeLog) -> list[Event]:
        """The collision events of ``log`` its ``CollisionTest`` counts, in time order."""

    @abstractmethod
    def time_budget(self, route_length: float) -> float:
        """An upper bound (s) on the simulated time an episode on a route of ``route_length`` m
        (the dense route's) can last before its route timeout."""

    @abstractmethod
    def leaderboard_file(self, records: Iterable[EpisodeRecord], agent: str, family: str,
                         key_points: KeyPoints | None = None, logs: Logs | None = None) -> dict:
        """The episodes of one agent and family as the leaderboard's results file (JSON-ready).
        ``key_points``: route id -> the route file's waypoints (m), where known, for a file
        whose route length is theirs; ``logs``: a crashed episode's stored log (its steps up to
        the crash; None: none), for a file that scores what its criteria had computed."""

    def route_infractions(self, log: EpisodeLog, mon: TerminationMonitor | None) -> list[Infraction]:
        """The infractions of the route criteria's finished monitor: outside route lanes, only
        when route advance was made off the lanes (``1 - pct / 100``)."""
        if mon is None or mon.outside_m <= 0:
            return []
        return [Infraction(EventKind.OUTSIDE_ROUTE_LANES, 1.0 - mon.outside_pct / 100.0, log.t[-1],
                           mon.progress, f"{mon.outside_m:.3f} m")]

    # ------------------------------------------------------------------ derived
    def monitor(self, route: DenseRoute, start_t: float) -> TerminationMonitor:
        """A fresh monitor of these route criteria, the route timeout running from ``start_t`` (s)."""
        return TerminationMonitor(route, start_t, self.rules)

    def max_steps(self, route_length: float, step_length: float) -> int:
        """A bound on an episode's simulation steps of ``step_length`` s (the route criteria end
        it first): :meth:`time_budget` plus 10 s, plus 10 steps."""
        return int((self.time_budget(route_length) + BUDGET_MARGIN_S) / step_length) + BUDGET_MARGIN_STEPS

    def ended_by(self, log: EpisodeLog) -> tuple[EpisodeLog, bool]:
        """The log as a run under these rules would have recorded it, and whether that is exact
        (:func:`~icrsumo.scoring.criteria.ended_by`)."""
        return ended_by(log, self.rules)

    def penalised_events(self, log: EpisodeLog) -> list[Event]:
        """The events of ``log`` these rules penalise, in time order: the collisions
        :meth:`counted_collisions` counts (a contact is logged on every step of it), and every
        red-light and stop-sign event (the sensors emit each once, as the leaderboard charges
        it). Unknown event kinds raise ValueError."""
        check_event_kinds(log)
        chosen = self.counted_collisions(log) + [e for e in log.events if e.kind in RULE_EVENTS]
        return sorted(chosen, key=lambda ev: ev.t)

    def penalised_infractions(self, log: EpisodeLog) -> tuple[Infraction, ...]:
        """:meth:`penalised_events` as infractions with their factors."""
        return tuple(Infraction(kind=EventKind(e.kind), factor=PENALTIES[e.kind], t=e.t, pos=e.pos,
                                other=e.other) for e in self.penalised_events(log))

    def score(self, log: EpisodeLog) -> EpisodeResult:
        """The scores of one episode: the log replayed (and cut where these rules end it),
        RC from the route criteria, IS the product of the penalised events' and the route
        criteria's factors, DS = RC x IS."""
        log, _, mon = cut_at_end(log, self.rules)
        infractions = [*self.penalised_infractions(log), *self.route_infractions(log, mon)]
        rc = mon.completion_pct if mon is not None else 0.0
        pct = mon.outside_pct if mon is not None else 0.0
        return episode_result(log, rc, pct, tuple(infractions), mon.outside_m if mon is not None else 0.0)
