"""What the leaderboard results files (``leaderboard/<agent>_<family>.json``) of Leaderboard
1.0 and 2.0 share: the records of one agent and family in the leaderboard's order, a record's
status and the infraction entry its termination adds, the entry of each penalised event, a
record with the scores of a log (a crashed episode's partial log included), and 1.0's labels
(2.0 extends them). Each version's file: :mod:`icrsumo.scoring.lb1`, :mod:`icrsumo.scoring.lb2`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import replace

from icrsumo.core.types import EpisodeLog, EpisodeRecord, EpisodeResult
from icrsumo.core.vocab import EpisodeStatus, EventKind, Termination

#: penalised event kind -> (infraction key, message)
EVENT_ENTRIES = {
    EventKind.COLLISION_PEDESTRIAN: ("collisions_pedestrian", "Agent collided against a pedestrian"),
    EventKind.COLLISION_VEHICLE: ("collisions_vehicle", "Agent collided against a vehicle"),
    EventKind.COLLISION_STATIC: ("collisions_layout", "Agent collided against the static layout"),
    EventKind.RED_LIGHT: ("red_light", "Agent ran a red light"),
    EventKind.STOP_SIGN: ("stop_infraction", "Agent ran a stop sign"),
}
#: termination -> (status, infraction key, message)
TERMINATION_STATUS = {
    Termination.COMPLETED: ("Completed", None, ""),
    Termination.ROUTE_DEVIATION: ("Failed - Agent deviated from the route", "route_dev",
                                  "Agent deviated from the route"),
    Termination.ROUTE_TIMEOUT: ("Failed - Agent timed out", "route_timeout", "Route timeout."),
    Termination.AGENT_BLOCKED: ("Failed - Agent got blocked", "vehicle_blocked", "Agent got blocked"),
    Termination.STUCK: ("Failed - Agent got blocked", "vehicle_blocked",
                        "Agent got stuck (SUMO teleported the ego)"),
    Termination.SIM_ERROR: ("Failed - Simulation crashed", None, ""),
}
#: Leaderboard 1.0's labels of the file's ``values``
LABELS = ["Avg. driving score", "Avg. route completion", "Avg. infraction penalty",
          "Collisions with pedestrians", "Collisions with vehicles", "Collisions with layout",
          "Red lights infractions", "Stop sign infractions", "Off-road infractions", "Route deviations",
          "Route timeouts", "Agent blocked"]

#: (record, infraction kind, factor) -> (infraction key, message) for the kinds a version words
#: itself, else None
Wording = Callable[[EpisodeRecord, str, float], tuple[str, str] | None]
#: an episode's stored log by its record (None: none stored)
Logs = Callable[[EpisodeRecord], EpisodeLog | None]


def with_scores(rec: EpisodeRecord, r: EpisodeResult) -> EpisodeRecord:
    """``rec`` with the scores, termination, infractions and duration of ``r``."""
    return replace(rec, ds=r.ds, rc=r.rc, is_=r.is_, termination=r.termination,
                   termination_class=r.termination_class.value,
                   infractions=tuple((i.kind, i.factor) for i in r.infractions), duration=r.duration,
                   outside_m=r.outside_m)


def crash_scored(records: Iterable[EpisodeRecord], logs: Logs | None,
                 score: Callable[[EpisodeLog], EpisodeResult]) -> list[EpisodeRecord]:
    """``records``, each crashed one that ``logs`` holds a log of (its steps up to the crash)
    with that log's scores by ``score`` (:func:`with_scores`; status and message kept): what
    the leaderboard's criteria had computed when the agent crashed. A crashed record without a
    log stays unscored (no termination)."""
    out = []
    for r in records:
        log = logs(r) if logs is not None and r.status == EpisodeStatus.CRASHED else None
        out.append(with_scores(r, score(log)) if log is not None and log.t else r)
    return out


def agent_records(records: Iterable[EpisodeRecord], agent: str, family: str) -> list[EpisodeRecord]:
    """The records of ``agent`` and ``family`` sorted by (route_id, k, seed)."""
    return sorted((r for r in records if r.agent == agent and r.family == family),
                  key=lambda r: (r.route_id, r.k, r.seed))


def route_name(r: EpisodeRecord) -> str:
    """The record's ``route_id`` in the file: ``RouteScenario_<route>_<family>_<k>``."""
    return f"RouteScenario_{r.route_id}_{r.family}_{r.k}"


#: how a crashed episode's message begins when the simulation failed, not the agent: SUMO
#: failed to start (libsumo raised), or the worker process running the episode died
SIMULATION_FAILURES = ("SimulatorError:", "WorkerDied:")


def route_status(r: EpisodeRecord) -> tuple[str, str | None, str]:
    """A record's leaderboard status, the infraction key its termination adds and that entry.
    A crashed episode is the simulation's crash when its message names one of
    :data:`SIMULATION_FAILURES`, else the agent's (its code raised, it timed out or broke the
    protocol: what the leaderboard reports as 'Agent crashed'); a crashed episode scored from
    its partial log whose rules had ended the route before the crash (rescored by other rules:
    :func:`crash_scored`) has that ending's status."""
    if r.status == EpisodeStatus.CRASHED and r.termination in ("", Termination.AGENT_ERROR):
        sim = r.message.startswith(SIMULATION_FAILURES)
        return ("Failed - Simulation crashed" if sim else "Failed - Agent crashed", None, "")
    return TERMINATION_STATUS.get(r.termination, (f"Failed - {r.termination}", None, ""))


def record_infractions(r: EpisodeRecord, keys: Sequence[str], wording: Wording
                       ) -> tuple[str, dict[str, list[str]]]:
    """A record's status and its infraction entries under ``keys`` (none for a crashed
    episode, unless scored from its partial log: :func:`crash_scored`): each stored infraction
    as ``wording`` words it, else as a penalised event (``<message> (penalty <factor>)``), then
    the entry its termination adds."""
    infr: dict[str, list[str]] = {k: [] for k in keys}
    status, key, msg = route_status(r)
    for kind, factor in r.infractions:
        worded = wording(r, kind, factor)
        if worded is None:
            lb_key, text = EVENT_ENTRIES.get(kind, ("collisions_layout", f"Agent infraction {kind}"))
            worded = lb_key, f"{text} (penalty {factor:.2f})"
        infr[worded[0]].append(worded[1])
    if key is not None:
        infr[key].append(msg)
    return status, infr
