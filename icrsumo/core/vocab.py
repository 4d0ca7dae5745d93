"""Every vocabulary of icrsumo, defined once: event kinds, terminations and their classes,
instruction families, intents, episode statuses, error kinds and the phases of a run's profile.

Members are :class:`enum.StrEnum`: each is its value as a string (``EventKind.RED_LIGHT ==
"red_light"``, ``str()`` and f-strings give the value, JSON writes the value), so stored files
and tables are the same text as before the enums existed, and a string read from a file
converts with ``EventKind(text)`` (a ``ValueError`` names an unknown value).
"""

from __future__ import annotations

from enum import StrEnum


class EventKind(StrEnum):
    """What an :class:`~icrsumo.core.types.Event` records. Penalised (Leaderboard 1.0): the
    collisions, red lights and stop signs; recorded only: the rest."""

    COLLISION_PEDESTRIAN = "collision_pedestrian"
    COLLISION_VEHICLE = "collision_vehicle"
    COLLISION_STATIC = "collision_static"
    RED_LIGHT = "red_light"
    STOP_SIGN = "stop_sign"
    WRONG_WAY = "wrong_way"
    LANE_INVASION = "lane_invasion"
    TELEPORT_BACKGROUND = "teleport_background"
    EGO_TELEPORT = "ego_teleport"
    SIM_ERROR = "sim_error"
    #: not an event: the infraction that OutsideRouteLanesTest's percentage becomes
    OUTSIDE_ROUTE_LANES = "outside_route_lanes"
    #: not an event: a checkpoint of Leaderboard 2.0's MinimumSpeedRouteTest below 100 %
    MIN_SPEED = "min_speed"


class TerminationClass(StrEnum):
    """ICR-Drive's failure classes: done, route deviation (RD) or timeout-like (TO)."""

    DONE = "done"
    RD = "RD"
    TO = "TO"


class Termination(StrEnum):
    """Why an episode ended (Leaderboard 1.0's rules, :mod:`icrsumo.scoring.criteria`). completed:
    more than 99 % of the route and within 10 m of its end; route_deviation: 30 m or more from
    the route, or more than 30 % of the route advanced while 15 m or more from it;
    agent_blocked: more than 180 s since the ego last moved at 0.1 m/s or more; route_timeout:
    int(0.8 s per metre + 5 s) elapsed; stuck: SUMO teleported the ego; sim_error: the
    simulator failed; agent_error: the agent (or its instruction guard) raised, timed out or
    broke the protocol (the log of a crashed episode, up to its last step)."""

    COMPLETED = "completed"
    ROUTE_DEVIATION = "route_deviation"
    AGENT_BLOCKED = "agent_blocked"
    ROUTE_TIMEOUT = "route_timeout"
    STUCK = "stuck"
    SIM_ERROR = "sim_error"
    AGENT_ERROR = "agent_error"

    @property
    def cls(self) -> TerminationClass:
        """The ICR-Drive class of this termination."""
        return TERMINATION_CLASS[self]


#: termination -> its ICR-Drive class
TERMINATION_CLASS: dict[Termination, TerminationClass] = {
    Termination.COMPLETED: TerminationClass.DONE,
    Termination.ROUTE_DEVIATION: TerminationClass.RD,
    Termination.AGENT_BLOCKED: TerminationClass.TO,
    Termination.ROUTE_TIMEOUT: TerminationClass.TO,
    Termination.STUCK: TerminationClass.TO,
    Termination.SIM_ERROR: TerminationClass.TO,
    Termination.AGENT_ERROR: TerminationClass.TO,
}


class Family(StrEnum):
    """An instruction sequence's family: the baseline, one of ICR-Drive's four counterfactual
    families, or a control family (does the agent use language at all?): ``blank`` (no
    instruction text) and ``shuffled`` (each instruction replaced by a baseline instruction of
    another maneuver), or a delivery family (when and how the baseline's instructions
    arrive: ``timing``, ``distance``, ``correction``, ``notice``)."""

    BASELINE = "baseline"
    PARAPHRASE = "paraphrase"
    AMBIGUITY = "ambiguity"
    NOISE = "noise"
    MISLEADING = "misleading"
    BLANK = "blank"
    SHUFFLED = "shuffled"
    TIMING = "timing"
    DISTANCE = "distance"
    CORRECTION = "correction"
    NOTICE = "notice"
    #: ``icrsumo attack``'s queries (k = the query) and the transfer of its worst rewrites
    ATTACK = "attack"
    TRANSFER = "transfer"


#: the four counterfactual families, in the paper's order (the default selection)
FAMILIES: tuple[Family, ...] = (Family.PARAPHRASE, Family.AMBIGUITY, Family.NOISE, Family.MISLEADING)
#: the control families, selectable like the four
CONTROL_FAMILIES: tuple[Family, ...] = (Family.BLANK, Family.SHUFFLED)
#: the delivery families (issue 45), selectable like the controls
DELIVERY_FAMILIES: tuple[Family, ...] = (Family.TIMING, Family.DISTANCE, Family.CORRECTION, Family.NOTICE)
#: every counterfactual family, in their canonical order (the paper's four, the controls, then
#: the delivery families)
ALL_FAMILIES: tuple[Family, ...] = FAMILIES + CONTROL_FAMILIES + DELIVERY_FAMILIES
#: one line per selectable family (``icrsumo list families``)
FAMILY_DESCRIPTIONS: dict[Family, str] = {
    Family.PARAPHRASE: "the same maneuver, worded otherwise (goal kept)",
    Family.AMBIGUITY: "the direction left out or vague (goal kept, harder to resolve)",
    Family.NOISE: "typos, case and punctuation noise (goal kept)",
    Family.MISLEADING: "a directive that contradicts the route (goal-conflicting)",
    Family.BLANK: "no instruction text at all",
    Family.SHUFFLED: "each instruction replaced by one of another maneuver",
    Family.TIMING: "the baseline text delivered late, or early across a junction (goal kept)",
    Family.DISTANCE: "the maneuver named by its distance or by ordinal, true to the route (goal kept)",
    Family.CORRECTION: "a misleading instruction, corrected before the junction (goal kept in the end)",
    Family.NOTICE: "notices (lights, pedestrians, merging traffic, ...) between the instructions (goal kept)",
}


def variants_of(family: str, k: int) -> int:
    """How many variants of ``family`` a K-variant protocol runs: ``blank`` has one (its K
    variants would be the same sequence), every other family K."""
    return 1 if family == Family.BLANK else k


class Intent(StrEnum):
    """What an instruction asks the driver to do next."""

    LEFT = "left"
    RIGHT = "right"
    STRAIGHT = "straight"
    FOLLOW = "follow"
    LANE_LEFT = "lane_left"
    LANE_RIGHT = "lane_right"
    STOP = "stop"
    UNKNOWN = "unknown"


class Verdict(StrEnum):
    """An instruction guard's decision on a new instruction: shown to the agent, not shown,
    or replaced by a repaired text (the guard's own, or the navigation plan's words under the
    ``navigator`` block policy: :mod:`icrsumo.guards.stream`)."""

    PASS = "pass"
    BLOCK = "block"
    REPAIR = "repair"


class DecisionOutcome(StrEnum):
    """What the ego did at one decision point of its route (a junction where the route has a
    choice, or a lane change it requires): ``followed_route``; ``followed_text`` (the text and
    the route disagree and the ego did what the text said); ``other`` (left the route some other
    way); ``not_reached`` (the episode ended before)."""

    FOLLOWED_ROUTE = "followed_route"
    FOLLOWED_TEXT = "followed_text"
    OTHER = "other"
    NOT_REACHED = "not_reached"


class EpisodeStatus(StrEnum):
    """A stored episode: ``done`` (scored) or ``crashed`` (the agent or the simulator failed)."""

    DONE = "done"
    CRASHED = "crashed"


class ErrorKind(StrEnum):
    """Why an episode produced no log: ``agent_timeout`` (an agent call overran its limit: not
    retried), ``worker_died`` (the worker process exited), ``error`` (anything raised)."""

    ERROR = "error"
    AGENT_TIMEOUT = "agent_timeout"
    WORKER_DIED = "worker_died"


class OutcomeStatus(StrEnum):
    """What running one episode job gave: ``done`` (a log and a record), ``crashed`` (an error
    of ``ErrorKind``), ``timed_out`` (an agent call overran ``--agent-timeout``)."""

    DONE = "done"
    CRASHED = "crashed"
    TIMED_OUT = "timed_out"


class Phase(StrEnum):
    """Where an evaluation's worker time goes (``EvalOptions.profile``, ``tools/benchmark.py
    --protocol``; never stored). Process start: ``worker_start`` (a worker process until its
    first job), ``episode_setup`` (scenario and instruction files, network, sensors, guard),
    ``agent_load`` (the agent made, its checkpoint loaded, reset), ``sumo_start`` (SUMO started,
    traffic warmed up, the ego inserted; SUMO closed). The closed loop, per step: ``sumo_step``
    (SUMO's step and its collision list), ``sumo_io`` (the ego moved by ``moveToXY``, the
    frame read), ``control`` (controller, bicycle model), ``observation`` (sensors, route
    progress, instruction stream, notice, World view), ``bev`` (the raster), ``act`` (the
    agent's ``act``), ``rules`` (the route criteria that end an episode), ``recording`` (the
    log's columns). Per episode: ``scoring`` (the log scored), ``logging`` (the log built and
    written as JSON). Around the jobs: ``storing`` (between two jobs of a worker: the parent
    stores the episode and sends the next job), ``idle`` (a worker without a job while others
    finish), ``before`` / ``after`` (the parent alone: checks, suite and plan / outputs),
    ``other`` (none of these)."""

    WORKER_START = "worker_start"
    EPISODE_SETUP = "episode_setup"
    AGENT_LOAD = "agent_load"
    SUMO_START = "sumo_start"
    SUMO_STEP = "sumo_step"
    SUMO_IO = "sumo_io"
    CONTROL = "control"
    OBSERVATION = "observation"
    BEV = "bev"
    ACT = "act"
    RULES = "rules"
    RECORDING = "recording"
    SCORING = "scoring"
    LOGGING = "logging"
    STORING = "storing"
    IDLE = "idle"
    BEFORE = "before"
    AFTER = "after"
    OTHER = "other"
