"""Deprecated: moved to :mod:`icrsumo.scoring` (``icrsumo.scoring.score_episode``, the rule sets in
:mod:`icrsumo.scoring.lb1` / :mod:`icrsumo.scoring.lb2`); these names are re-exported from there.
"""

from __future__ import annotations

from icrsumo.scoring import DEFAULT_SCORING, SCORINGS, Scoring, register_scoring, score_episode, scoring_names
from icrsumo.scoring.criteria import ended_by
from icrsumo.scoring.lb1 import (
           LB1,
           MAX_AREA_OF_COLLISION,
           MIN_AREA_OF_COLLISION,
           CollisionCounter,
           counted_collisions,
)
from icrsumo.scoring.lb2 import MIN_SPEED_FACTOR, CollisionCounter2, counted_collisions_lb2
from icrsumo.scoring.penalties import COLLISIONS, EVENT_KINDS, MAX_ID_TIME, NON_PENALISED, PENALTIES

#: Leaderboard 1.0's penalised event infractions of a log
#: (:meth:`icrsumo.scoring.base.Scoring.penalised_infractions`)
penalised_infractions = LB1.penalised_infractions

__all__ = ["COLLISIONS", "DEFAULT_SCORING", "EVENT_KINDS", "MAX_AREA_OF_COLLISION", "MAX_ID_TIME",
           "MIN_AREA_OF_COLLISION", "MIN_SPEED_FACTOR", "NON_PENALISED", "PENALTIES", "SCORINGS",
           "CollisionCounter", "CollisionCounter2", "Scoring", "counted_collisions", "counted_collisions_lb2",
           "ended_by", "penalised_infractions", "register_scoring", "score_episode", "scoring_names"]
