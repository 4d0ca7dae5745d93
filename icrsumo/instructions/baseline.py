"""Baseline LangAuto-style instruction sequences from a route's maneuvers.

Layout along the route (positions in m):

- a ``start`` instruction at 0 (dropped when the first maneuver is announced right away);
- per junction maneuver, when there is room (35 m free before it), a far announcement with a
  distance (``turn_distance``, ``straight_distance``, ``highway_exit_distance``) 80 m before
  (150 m for highway exits) and a near one qualified by the junction kind
  (``turn_traffic_light``, ``turn_t_junction``, ``roundabout_exit``, ...) 20 m before;
  otherwise one instruction 50 m before (or as soon as the previous maneuver is done);
- lane changes at the start of the edge where the route needs them (earlier where that edge is
  too short to change on: :func:`.maneuvers.lane_change_pos`), with the distance left to
  the junction where the lane matters when that is 30 m or more, kept on for 30 m per lane to
  cross (at most half the room before that junction);
- follow instructions over gaps of 30 m or more between maneuvers and after the last one;
- no instruction replaces a junction maneuver's before the ego has left that junction (its
  internal lanes' end plus 5 m; for a roundabout, the exit junction's), unless the next
  junction comes sooner: then the next instruction starts at the exit, or 5 m before the next
  junction, whichever is later; where the next junction is less than 20 m past the exit (CARLA's
  towns have junctions a few metres apart), the driver must know it while still in the last
  junction: its instruction starts 20 m before it, but not before the ego has entered the last
  junction (1 m past its entry; for a roundabout, 20 m before its exit);
- a lane change across n lanes is n instructions, one per lane, spread over 30 m per lane;
- notices beside the instructions: traffic lights and stop signs 40 m before the junction,
  pedestrians at signalised or stop-controlled junctions with crossings.

For training data only (``icrsumo collect --vary-leads``), a second Generator may draw each
junction maneuver's announcement distances from :data:`VARIED_LEADS` instead (the fixed ones
lie inside its ranges), so that a network sees a turn's text arrive before other openings than
the one it names; the benchmark's own sequences never do.

Phrasings are drawn from the baseline bank with a Generator seeded by the route seed; distances
are rounded to 10 m. With a LangAuto-style bank (``--baseline-bank``, :mod:`.baseline_bank`)
the text of every type it maps is then replaced by one of its phrasings, drawn by a second
Generator seeded with (route seed, LANGAUTO_STREAM): the sequence's layout (types, triggers,
distances, notices) and icrsumo's own draws stay exactly those without the bank.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from icrsumo.core.types import Instruction, InstructionSet, Intent, Maneuver, Notice
from icrsumo.core.vocab import Family

from .banks import ORDINALS, Banks, fill

if TYPE_CHECKING:
    from .baseline_bank import BaselineBank

#: version of the layout rules above, stored with generated instructions (1: before lane changes
#: were moved off short edges, split per lane and junctions a few metres apart announced early)
LAYOUT_VERSION = 2
FAR_M, NEAR_M, SINGLE_M = 80.0, 20.0, 50.0
TWO_STAGE_ROOM_M = 35.0
FOLLOW_GAP_M = 30.0
AFTER_M = 10.0
#: distance (m) past a junction's exit before the next instruction replaces its maneuver's
AFTER_EXIT_M = 5.0
NOTICE_M = 40.0
#: a junction closer than this (m) to the last maneuver's exit is announced inside that junction
NEXT_ROOM_M = 20.0
#: distance (m) a lane change instruction stays on before the next one, per lane to cross
LANE_CHANGE_M = 30.0
HIGHWAY_EXIT_FAR_M = 150.0
#: second seed word of the Generator that draws --baseline-bank phrasings ("LANG")
LANGAUTO_STREAM = 0x4C414E47


class Leads(NamedTuple):
    """Announcement distances (m before a junction maneuver): ``single`` instruction, two-stage
    ``far`` and ``near`` ones, a highway exit's far one, and ``next_room``, under which a junction
    that follows the last one's exit is announced inside the last one."""

    single: float
    far: float
    near: float
    highway_far: float
    next_room: float


#: the benchmark's layout (module docstring)
FIXED_LEADS = Leads(SINGLE_M, FAR_M, NEAR_M, HIGHWAY_EXIT_FAR_M, NEXT_ROOM_M)
#: (low, high) m of each lead drawn uniformly per junction maneuver for varied-lead training data
VARIED_LEADS: dict[str, tuple[float, float]] = {
    "single": (20.0, 90.0), "far": (60.0, 120.0), "near": (10.0, 35.0),
    "highway_far": (100.0, 200.0), "next_room": (20.0, 50.0)}
#: second seed word of the Generator that draws varied leads ("LEAD")
LEAD_STREAM = 0x4C454144


def draw_leads(rng: np.random.Generator) -> Leads:
    """One junction maneuver's leads, each uniform in its :data:`VARIED_LEADS` range (m)."""
    return Leads(**{k: float(rng.uniform(*VARIED_LEADS[k])) for k in Leads._fields})


_JUNCTION_TYPE = {"traffic_light": "traffic_light", "t_junction": "t_junction",
                  "crossroad": "intersection", "stop_sign": "stop_sign"}


def _round10(d: float) -> float:
    return float(max(10, int(round(d / 10.0)) * 10))


class _Builder:
    def __init__(self, banks: Banks, rng: np.random.Generator, user: BaselineBank | None = None,
                 user_rng: np.random.Generator | None = None) -> None:
        self.banks, self.rng, self.user, self.user_rng = banks, rng, user, user_rng
        self.items: list[Instruction] = []

    def text(self, itype: str, slots: dict[str, str]) -> str:
        """icrsumo's phrasing drawn by the route's Generator; replaced by one of the user's
        LangAuto phrasings (drawn by their own Generator) where the bank maps the type."""
        phrasings = self.banks.baseline[itype]
        text = fill(phrasings[int(self.rng.integers(len(phrasings)))], **slots)
        theirs = self.user.phrasings_for(itype, slots) if self.user is not None else None
        if theirs and self.user_rng is not None:
            text = theirs[int(self.user_rng.integers(len(theirs)))]
        return text

    def add(self, itype: str, trigger: float, intent: Intent, m: Maneuver | None = None,
            distance: float | None = None, **slots: str) -> None:
        text = self.text(itype, slots)
        # the first instruction is active from the start; later ones strictly after each other
        trigger = max(trigger, self.items[-1].trigger + 1.0) if self.items else 0.0
        self.items.append(Instruction(
            id=len(self.items), trigger=round(trigger, 2), text=text, intent=intent, type=itype,
            distance=_round10(distance) if distance is not None else None,
            maneuver_pos=None if m is None else round(m.pos, 2),
            junction="" if m is None else m.junction,
        ))


def _near_type(m: Maneuver) -> tuple[str, dict[str, str]]:
    """Junction-qualified instruction type and slots for a maneuver."""
    if m.kind == "roundabout":
        return "roundabout_exit", {"exit": ORDINALS[min(m.exit, len(ORDINALS)) - 1]}
    if m.kind == "highway_exit":
        return "highway_exit", {}
    if m.kind == "highway_enter":
        return "highway_enter", {}
    qual = _JUNCTION_TYPE.get(m.junction)
    if m.kind == "straight":
        return ("straight_" + qual if qual in ("intersection", "traffic_light", "stop_sign")
                else "straight"), {}
    direction = "left" if m.intent == Intent.LEFT else "right"
    return (f"turn_{qual}" if qual else "turn"), {"dir": direction}


def _far_type(m: Maneuver) -> tuple[str, dict[str, str]] | None:
    if m.kind in ("turn_left", "turn_right"):
        return "turn_distance", {"dir": "left" if m.intent == Intent.LEFT else "right"}
    if m.kind == "straight":
        return "straight_distance", {}
    if m.kind == "highway_exit":
        return "highway_exit_distance", {}
    return None


def build_baseline(
    route_id: str, length: float, maneuvers: list[Maneuver], banks: Banks, seed: int,
    highway_spans: tuple[tuple[float, float], ...] = (),
    crossing_junctions: frozenset[str] = frozenset(),
    baseline_bank: BaselineBank | None = None,
    lead_rng: np.random.Generator | None = None,
) -> InstructionSet:
    """The baseline sequence of one route (``length`` in m) from its sorted maneuvers.

    ``highway_spans``: (start, end) route positions (m) driven on a highway (for the
    follow_highway types); ``crossing_junctions``: junction ids with pedestrian crossings;
    ``baseline_bank``: LangAuto's phrasings for the types it maps (None: icrsumo's own);
    ``lead_rng``: draws each junction maneuver's :class:`Leads` (training data only; None: the
    fixed layout). Phrasings are the same with and without it.
    """
    rng = np.random.default_rng(seed)
    user_rng = np.random.default_rng([seed, LANGAUTO_STREAM]) if baseline_bank is not None else None
    b = _Builder(banks, rng, baseline_bank, user_rng)
    turns = [m for m in maneuvers if not m.kind.startswith("lane_change")]
    cursor = 0.0
    first_announce = min((max(0.0, m.pos - SINGLE_M) for m in maneuvers), default=length)
    if first_announce > 15.0:
        b.add("start", 0.0, Intent.FOLLOW)
    def follow(at: float, until: float) -> None:
        mid = (at + until) / 2
        on_hw = any(a <= mid < b for a, b in highway_spans)
        base = "follow_highway" if on_hw else "follow"
        if rng.random() < 0.5:
            b.add(base + "_distance", at, Intent.FOLLOW, distance=until - at)
        else:
            b.add(base, at, Intent.FOLLOW)

    exit_pos = 0.0  # where the last junction maneuver's junction was left (m)
    inside: float | None = None  # a route position (m) inside that junction
    for m in maneuvers:
        if m.kind.startswith("lane_change"):
            side = "left" if m.intent == Intent.LANE_LEFT else "right"
            deadline = next((t.pos for t in turns if t.pos > m.pos), length)
            start = max(cursor, m.pos)
            room = deadline - start
            # leave the lane change on screen for a while (30 m per lane to cross) before the
            # next announcement; one instruction per lane, as the phrasings name one lane
            n = max(m.lanes, 1)
            span = min(LANE_CHANGE_M * n, max(1.0, 0.5 * room))
            if room >= 30.0 and rng.random() < 0.5:
                b.add("lane_change_distance", start, m.intent, m, distance=room, side=side)
            else:
                b.add("lane_change", start, m.intent, m, side=side)
            for i in range(1, n):
                b.add("lane_change", start + span * i / n, m.intent, m, side=side)
            cursor = start + span
            continue
        lead = FIXED_LEADS if lead_rng is None else draw_leads(lead_rng)
        if inside is not None and m.pos - exit_pos < lead.next_room:
            # the junction follows the last one so closely that the driver must know it while
            # still in the last one: announce it there, lead.next_room before it at the latest
            # (NEXT_ROOM_M in the fixed layout)
            cursor = max(inside, min(cursor, m.pos - lead.next_room))
        elif m.pos < cursor:
            # the junction comes soon after the last maneuver: announce it as soon as the
            # last junction is left, at the latest 5 m before this one
            cursor = max(exit_pos, min(cursor, m.pos - AFTER_EXIT_M))
        far_m = lead.highway_far if m.kind == "highway_exit" else lead.far
        far = _far_type(m)
        announce = max(cursor, m.pos - (far_m if far else lead.single))
        if announce - cursor >= FOLLOW_GAP_M:
            follow(cursor, announce)
        if far is not None and m.pos - announce >= TWO_STAGE_ROOM_M:
            itype, slots = far
            b.add(itype, announce, m.intent, m, distance=m.pos - announce, **slots)
            itype, slots = _near_type(m)
            # at least 10 m after the far one (the fixed layout: 15 m or more)
            b.add(itype, m.pos - min(lead.near, m.pos - announce - 10.0), m.intent, m, **slots)
        else:
            itype, slots = _near_type(m)
            b.add(itype, announce, m.intent, m, **slots)
        exit_pos = max(m.pos, m.end)
        # in a roundabout, the exit junction (the ring's exit count must hold until then)
        inside = m.pos + 1.0 if m.kind != "roundabout" else max(m.pos + 1.0, exit_pos - NEXT_ROOM_M)
        cursor = max(m.pos + AFTER_M, m.end + AFTER_EXIT_M)
    if length - cursor >= FOLLOW_GAP_M or not b.items:
        follow(min(cursor, length), length)

    notices: list[Notice] = []
    for m in turns:
        for ntype, ok in (("notice_traffic_light", m.junction == "traffic_light"),
                          ("notice_stop_sign", m.junction == "stop_sign"),
                          ("notice_pedestrians", m.junction_id in crossing_junctions
                           and m.junction in ("traffic_light", "stop_sign") and rng.random() < 0.5)):
            if ok:
                notices.append(Notice(
                    id=len(notices), trigger=round(max(0.0, m.pos - NOTICE_M), 2),
                    end=round(max(m.pos + AFTER_M, m.end), 2), text=b.text(ntype, {}),
                    type=ntype, intent=Intent.STOP,
                ))
    return InstructionSet(route_id=route_id, family=Family.BASELINE, k=0, seed=seed,
                          instructions=tuple(b.items), notices=tuple(notices))
