"""The registry of scoring rule sets: name (what users pass to ``--scoring``) ->
:class:`~icrsumo.scoring.base.Scoring`. A name is registered once. The mechanism only: the
rule sets are registered by :mod:`icrsumo.scoring` (``lb1``, ``lb2``); a third one is a
:class:`~icrsumo.scoring.base.Scoring` subclass in its own module, registered there.
"""

from __future__ import annotations

from collections.abc import Sequence

from icrsumo.core.types import EpisodeLog, EpisodeResult

from .base import Scoring

#: name -> scoring (:func:`register_scoring` refuses a name twice)
SCORINGS: dict[str, Scoring] = {}

#: the default scoring
DEFAULT_SCORING = "lb1"


def register_scoring(scoring: Scoring) -> Scoring:
    """Add ``scoring`` to :data:`SCORINGS` under its name; ValueError when the name is taken."""
    if scoring.name in SCORINGS:
        raise ValueError(f"scoring {scoring.name!r} is registered already")
    SCORINGS[scoring.name] = scoring
    return scoring


def scoring_names() -> Sequence[str]:
    """The registered scoring names, default first."""
    return [DEFAULT_SCORING] + sorted(n for n in SCORINGS if n != DEFAULT_SCORING)


def get_scoring(name: str | None = None) -> Scoring:
    """The scoring registered as ``name`` (None or "": :data:`DEFAULT_SCORING`); ValueError naming
    the known ones otherwise."""
    try:
        return SCORINGS[name or DEFAULT_SCORING]
    except KeyError:
        raise ValueError(f"unknown scoring {name!r} (known: {', '.join(scoring_names())})") from None


def score_episode(log: EpisodeLog, scoring: str = DEFAULT_SCORING) -> EpisodeResult:
    """The scores of one episode under ``scoring`` (a name of :data:`SCORINGS`)."""
    return get_scoring(scoring).score(log)
