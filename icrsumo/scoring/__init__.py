"""Scoring: the leaderboards' rules, one rule set per module, registered by name
(docs/scoring.md).

- :mod:`~icrsumo.scoring.base`: :class:`Scoring`, what a rule set provides (route criteria,
  collision counting, step budget, per-episode score, leaderboard results file);
- :mod:`~icrsumo.scoring.registry`: name -> rule set, :func:`score_episode`;
- :mod:`~icrsumo.scoring.lb1` (CARLA Leaderboard 1.0, the default), :mod:`~icrsumo.scoring.lb2`
  (2.0): the rule sets, each whole;
- shared by them: :mod:`~icrsumo.scoring.criteria` (the route criteria monitor, also run by the
  closed loop), :mod:`~icrsumo.scoring.route` (the dense route),
  :mod:`~icrsumo.scoring.penalties` (IS factors, the rounded result) and
  :mod:`~icrsumo.scoring.leaderboard` (what the results files share).

Pure: no SUMO. The rule sets are registered here, apart from the registry's mechanism.
"""

from .base import Scoring
from .lb1 import LB1
from .lb2 import LB2
from .registry import DEFAULT_SCORING, SCORINGS, get_scoring, register_scoring, score_episode, scoring_names

register_scoring(LB1)
register_scoring(LB2)

__all__ = ["DEFAULT_SCORING", "SCORINGS", "Scoring", "get_scoring", "register_scoring", "score_episode",
           "scoring_names"]
