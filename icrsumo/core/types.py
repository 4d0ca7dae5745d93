"""Frozen records shared across icrsumo. Units: metres, seconds, radians unless stated."""

from __future__ import annotations

from dataclasses import dataclass

from .vocab import (
    TERMINATION_CLASS,
    EpisodeStatus,
    EventKind,
    Family,
    Intent,
    Termination,
    TerminationClass,
    Verdict,
)


@dataclass(frozen=True)
class Waypoint:
    """One leaderboard waypoint as written in the route file (file coordinates).

    ``yaw`` is in degrees as in the file, ``None`` when the file gives none.
    """

    x: float
    y: float
    z: float = 0.0
    pitch: float = 0.0
    roll: float = 0.0
    yaw: float | None = None


@dataclass(frozen=True)
class RouteSpec:
    """One ``<route>`` of a leaderboard route file.

    ``index`` is its 0-based position in the file; ``weather`` keeps the attributes of the
    first ``<weather>`` element verbatim, in file order.
    """

    id: str
    town: str
    waypoints: tuple[Waypoint, ...]
    weather: tuple[tuple[str, str], ...] = ()
    index: int = 0


@dataclass(frozen=True)
class LanePos:
    """A position on a SUMO lane: lane id, distance from the lane start (m), and the
    world pose there (x, y in m, heading in rad, counter-clockwise from +x)."""

    lane: str
    pos: float
    x: float
    y: float
    heading: float

    @property
    def edge(self) -> str:
        return self.lane.rsplit("_", 1)[0]

    @property
    def lane_index(self) -> int:
        return int(self.lane.rsplit("_", 1)[1])


@dataclass(frozen=True)
class JunctionPass:
    """The ego route crossing one junction from edge ``from_edge`` to ``to_edge``.

    ``direction`` is SUMO's connection direction (s, l, r, t, L, R: straight, left, right,
    turn-around, partly left, partly right); ``choice`` is True when ``from_edge`` offers more
    than one onward edge (a real maneuver). ``pos`` is the route position (m) of the junction
    entry. ``from_lane``/``to_lane`` are the lane indices of the connection used.
    """

    junction: str
    junction_type: str
    from_edge: str
    to_edge: str
    from_lane: int
    to_lane: int
    via: str
    direction: str
    choice: bool
    roundabout: bool
    pos: float


@dataclass(frozen=True)
class LaneChange:
    """A lane change the route requires on ``edge`` (lane indices: 0 is the rightmost)."""

    edge: str
    pos: float
    from_lane: int
    to_lane: int

    @property
    def direction(self) -> str:
        return "left" if self.to_lane > self.from_lane else "right"

    @property
    def lanes(self) -> int:
        """How many lanes the change crosses."""
        return abs(self.to_lane - self.from_lane)


@dataclass(frozen=True)
class EgoRoute:
    """The ego's planned route through a network.

    ``edges``: normal edge ids in driving order; ``lanes[i]``: indices of the lanes of
    ``edges[i]`` from which the route can continue; ``lane_path[i]``: the lane driven on
    ``edges[i]``; ``polyline``: (N, 2) centre line in m from start to end; ``length`` in m;
    ``headings``: (N,) rad, the direction of the lane at each polyline vertex (of the lane
    piece the vertex starts; the segments that join two lane pieces, such as a lane change's
    sideways step, have no lane of their own and keep the heading of the lane they leave).
    """

    edges: tuple[str, ...]
    lanes: tuple[tuple[int, ...], ...]
    lane_path: tuple[int, ...]
    start: LanePos
    end: LanePos
    polyline: tuple[tuple[float, float], ...]
    length: float
    junctions: tuple[JunctionPass, ...]
    lane_changes: tuple[LaneChange, ...]
    headings: tuple[float, ...] = ()


@dataclass(frozen=True)
class Maneuver:
    """One thing the route asks of the driver, at route position ``pos`` (m).

    ``kind``: turn_left, turn_right, straight, u_turn, roundabout, highway_enter, highway_exit,
    lane_change_left, lane_change_right or follow. ``junction``: the junction kind
    (traffic_light, stop_sign, t_junction, crossroad, roundabout, highway_entry, highway_exit,
    junction) or "" for lane changes and follow stretches. ``exit`` is the roundabout exit
    number (1 = first), ``length`` the extent (m) of a follow stretch. ``end`` is the route
    position (m) where the maneuver is over: the end of the junction's internal lanes (for a
    roundabout, of the exit junction's); 0 for lane changes and follow stretches. ``lanes`` is
    the number of lanes a lane change crosses (0 for the other kinds).
    """

    kind: str
    pos: float
    intent: Intent
    junction: str = ""
    junction_id: str = ""
    exit: int = 0
    length: float = 0.0
    end: float = 0.0
    lanes: int = 0


@dataclass(frozen=True)
class Instruction:
    """One navigation instruction of a sequence.

    ``trigger``: route position (m) from which it is active; ``text`` may hold the placeholder
    ``[x]``, filled with ``distance`` (m) when shown to the agent; ``intent``: the intent of
    the baseline maneuver it stands for; ``type``: the LangAuto-style instruction type.
    Variants also record the ``template`` (bank entry or noise-operation id) and the baseline
    ``source`` text they were made from.
    """

    id: int
    trigger: float
    text: str
    intent: Intent
    type: str
    distance: float | None = None
    maneuver_pos: float | None = None
    junction: str = ""
    template: str = ""
    source: str = ""

    def rendered(self) -> str:
        """The text as the agent sees it: ``[x]`` replaced by the distance in metres."""
        if self.distance is None:
            return self.text
        return self.text.replace("[x]", f"{self.distance:.0f}")


@dataclass(frozen=True)
class Notice:
    """A notice shown beside the instruction between route positions ``trigger`` and ``end``
    (m): a traffic light, a stop sign, pedestrians crossing ahead."""

    id: int
    trigger: float
    end: float
    text: str
    type: str
    intent: Intent = Intent.UNKNOWN


@dataclass(frozen=True)
class InstructionSet:
    """A full instruction sequence for one route: the baseline (``family='baseline'``, k=0)
    or counterfactual variant ``k`` of a family, with the baseline's ids and triggers."""

    route_id: str
    family: Family
    k: int
    seed: int
    instructions: tuple[Instruction, ...]
    notices: tuple[Notice, ...] = ()


#: termination kind -> class (see :class:`icrsumo.core.vocab.Termination`)
TERMINATIONS: dict[Termination, TerminationClass] = TERMINATION_CLASS


@dataclass(frozen=True)
class Event:
    """Something that happened at simulation time ``t`` (s) and route position ``pos`` (m).

    ``kind``: an :class:`EventKind` (collisions, red light, stop sign, wrong way, lane
    invasion, teleport_background: a background vehicle teleported (a jam), ego_teleport: SUMO
    removed the ego (stuck), sim_error).
    ``other``: the other actor or the junction / lane id; ``x``, ``y`` in m.
    """

    kind: EventKind
    t: float
    pos: float
    other: str = ""
    x: float = 0.0
    y: float = 0.0


@dataclass(frozen=True)
class ModelCall:
    """One question an agent asked its language model during an episode, and the answer:
    ``t`` (s) and the active ``instruction_id``; ``at``: what prompted it ("instruction": the
    instruction changed, "junction": a junction with a choice came within reach); ``key``: the
    SHA-256 of the exact request (its address in the response cache); ``prompt``: the user
    message (instruction and scene); ``answer``: the model's answer text (cut to 500
    characters; "" when there was none); ``maneuver``: what the agent did with it (follow for
    an invalid answer); ``valid``; ``problem``: why an answer is invalid ("" when valid)."""

    t: float
    instruction_id: int
    at: str
    key: str
    prompt: str
    answer: str
    maneuver: Intent
    valid: bool
    problem: str = ""


@dataclass(frozen=True)
class GuardDecision:
    """An instruction guard's decision on one new instruction: ``t`` (s) and route ``progress``
    (m) when it became active, its ``instruction_id``, the ``verdict`` (pass: shown to the agent;
    block: not shown, the agent keeps what it was shown before; repair: the repaired ``text`` is
    shown instead) and the guard's one-line ``reason``. ``baseline_id``: the id of the baseline
    instruction whose words a repair shows (-1: the guard's own text, or "Follow the road.")."""

    t: float
    progress: float
    instruction_id: int
    verdict: Verdict
    reason: str = ""
    text: str = ""
    baseline_id: int = -1


@dataclass(frozen=True)
class Ask:
    """An agent's ask for clarification (``Action.ask``, with asking on): ``t`` (s) and route
    ``progress`` (m) of the observation it answered, whether the navigator ``answered`` it (at
    most once per maneuver: a later ask about the same maneuver is counted, not answered) and
    the ``instruction_id`` of the baseline instruction it answered with (-1: not answered, or no
    maneuver left, answered "Follow the road.")."""

    t: float
    progress: float
    answered: bool
    instruction_id: int = -1


@dataclass(frozen=True)
class EpisodeLog:
    """Everything scoring needs from one closed-loop episode, serialisable to JSON.

    Per-step columns (equal length N, one entry per simulation step after the ego entered):
    ``t`` (s), ``x``/``y`` (m, ego centre), ``yaw`` (rad), ``speed`` (m/s), ``progress`` (m
    along the dense route, monotone: the last point passed), ``instruction`` (active
    instruction id, -1 none), ``outside`` (Leaderboard 1.0's OutsideRouteLanesTest flags of the
    step: bit 1 off every driving lane by more than lane width / 2 + 1.3 m, bit 2 in a lane of
    the opposite direction; bits 4 and 8 the same by Leaderboard 2.0's rules; 0 inside the
    lanes), ``route_dist`` (m, ego centre to the nearest
    of the next route points, as InRouteTest measures it). ``route_length`` (m): the dense
    route's length. ``route``: the route polyline (m; a third value per point: the lane's
    heading there, rad), from which the rules rebuild the dense route
    (:class:`icrsumo.scoring.route.DenseRoute`). Per step too, for Leaderboard 2.0's rules:
    ``traffic_speed`` (m/s, mean speed of the other vehicles, -1 when there are none) and
    ``speed_limit`` (m/s, of the nearest driving lane); empty in logs that do not record them.
    ``model_calls``: the agent's questions to a language model and their answers
    (:class:`ModelCall`; empty for agents without one, and then absent from the JSON).
    ``guard``: an instruction guard's decisions (:class:`GuardDecision`; empty and absent from
    the JSON without a guard); with a guard, ``instruction`` holds the id the agent was shown
    (the last passed one; -1 before any, or for the "follow the road" shown while none passed).
    ``asks``: the agent's asks for clarification (:class:`Ask`; empty, and absent from the JSON,
    when it asked none or asking was off). ``termination`` is a
    :class:`Termination`; ``t`` strictly increases, ``progress`` never decreases, and the
    route timeout runs from ``t[0]``.
    """

    route_id: str
    agent: str
    family: Family
    k: int
    seed: int
    step_length: float
    route_length: float
    t: tuple[float, ...]
    x: tuple[float, ...]
    y: tuple[float, ...]
    yaw: tuple[float, ...]
    speed: tuple[float, ...]
    progress: tuple[float, ...]
    instruction: tuple[int, ...]
    outside: tuple[int, ...]
    route_dist: tuple[float, ...]
    events: tuple[Event, ...]
    termination: Termination
    termination_t: float
    message: str = ""
    route: tuple[tuple[float, ...], ...] = ()
    traffic_speed: tuple[float, ...] = ()
    speed_limit: tuple[float, ...] = ()
    model_calls: tuple[ModelCall, ...] = ()
    guard: tuple[GuardDecision, ...] = ()
    asks: tuple[Ask, ...] = ()


@dataclass(frozen=True)
class Infraction:
    """A penalised infraction: its kind, the IS factor it applies (e.g. 0.6), when and where."""

    kind: EventKind
    factor: float
    t: float
    pos: float
    other: str = ""


@dataclass(frozen=True)
class EpisodeResult:
    """Leaderboard scores of one episode: RC and DS in 0-100, IS in 0-1; ``outside_lanes_pct``
    (%) and ``outside_m`` (m): the route advance made off the driving lanes or against the
    traffic, OutsideRouteLanesTest's."""

    route_id: str
    agent: str
    family: Family
    k: int
    rc: float
    is_: float
    ds: float
    termination: Termination
    termination_class: TerminationClass
    infractions: tuple[Infraction, ...]
    outside_lanes_pct: float
    duration: float
    outside_m: float = 0.0


@dataclass(frozen=True)
class EpisodeRecord:
    """One stored episode of an evaluation, keyed by (agent, route_id, family, k, seed).

    ``family`` is "baseline" (k = 0) or a counterfactual family; ``status`` is "done" or
    "crashed" (scores are then 0 and ``message`` says why). DS and RC in 0-100, IS in 0-1;
    ``termination_class`` is done, RD or TO; ``infractions`` holds (kind, factor) pairs;
    ``length`` (m) and ``duration`` (simulated s) describe the route and the episode;
    ``outside_m`` (m): the route advance made off the driving lanes or against the traffic.
    ``model_calls`` / ``invalid_answers``: the agent's questions to a language model and how
    many answers were invalid (0 for agents without one). ``guard_checked`` /
    ``guard_blocked``: instructions an instruction guard checked and blocked (0 without one;
    texts the family kept unchanged and empty texts are not counted; a repaired instruction is
    blocked too, and also counted in ``guard_repaired``). ``asks`` / ``asks_answered``: the
    agent's asks for clarification and how many the navigator answered (0 without asking).
    """

    agent: str
    route_id: str
    family: Family
    k: int
    seed: int
    status: EpisodeStatus
    ds: float = 0.0
    rc: float = 0.0
    is_: float = 0.0
    termination: Termination | str = ""
    termination_class: TerminationClass | str = ""
    infractions: tuple[tuple[str, float], ...] = ()
    length: float = 0.0
    duration: float = 0.0
    attempts: int = 1
    message: str = ""
    outside_m: float = 0.0
    model_calls: int = 0
    invalid_answers: int = 0
    guard_checked: int = 0
    guard_blocked: int = 0
    asks: int = 0
    asks_answered: int = 0
    guard_repaired: int = 0
