"""The delivery families (issue 45): the baseline's maneuvers, told at another moment or in
another way. Each is paired with the baseline on the same scenario, goal-preserving, and
checked with the intent classifier; docs/instructions.md (*Delivery families*) has examples.

- ``timing``: each junction maneuver's baseline text (the one active at the junction, when it
  reads as the maneuver) delivered *late*, :attr:`DeliveryParams.late_m` metres before the
  junction entry (drawn per variant), its earlier announcements dropped; in odd variants
  *early* where the route allows it:
  :attr:`DeliveryParams.early_m` metres before the junction that comes before the maneuver's,
  held across it, when that junction offers no choice (it asks nothing of the driver), lies
  past the previous maneuver's exit and no lane change comes between (else late).
- ``distance``: every instruction of a turn, straight crossing, roundabout or highway exit
  names it by its distance along the route from the instruction's trigger to the junction
  entry (rounded as navigators do: :func:`~.delivery_common.navigator_metres`) or, for turns,
  one instruction names it by its ordinal among the junctions ahead with a choice that offer
  that turn (``take the second right``; :func:`ordinal_run`).
- ``correction``: a misleading instruction (the misleading family's bank, asserted to
  contradict) at the maneuver's first trigger, then its correction (an opening phrase and the
  baseline's text at the junction, asserted to read as the maneuver's intent)
  :attr:`DeliveryParams.correction_m` metres before the junction entry (at least
  :data:`WRONG_M` after the misleading one, at least :data:`FIX_ROOM_M` before the junction).
- ``notice``: :mod:`.notices`.

Randomness: variant ``k`` of a family draws from a Generator seeded with ``(seed, crc32(route
id), the family's stream, k)``, and the entries of each maneuver are taken, variant by variant,
from one permutation per maneuver (seeded without ``k``): a variant does not depend on K nor on
the other families selected, so a folder whose K grows keeps its variants.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from icrsumo.core.types import Instruction, InstructionSet, Intent, JunctionPass, Maneuver
from icrsumo.core.vocab import Family
from icrsumo.world.networks import RoadNet

from .banks import CONTRADICTS, ORDINALS, Banks, fill
from .baseline import AFTER_EXIT_M
from .delivery_common import (
    DeliveryParams,
    Group,
    RouteView,
    Unbuildable,
    assemble,
    groups,
    is_lane_change,
    moved,
    permutations,
    variant_rng,
)
from .delivery_texts import (
    CORRECTION_PREFIXES,
    DISTANCE_HIGHWAY_EXIT,
    DISTANCE_ROUNDABOUT,
    DISTANCE_STRAIGHT,
    DISTANCE_TURN,
    ORDINAL_TURN,
)
from .families import assert_intent
from .intent import classify_intent
from .notices import notice_set

__all__ = ["DeliveryParams", "RouteView", "Unbuildable", "delivery_variants"]

#: an early instruction comes at least this far (m) before the junction it is held across
EARLY_BEFORE_M = 5.0
#: the misleading instruction of a correction is on for at least this long (m of route)
WRONG_M = 10.0
#: a correction comes at least this far (m) before the junction entry
FIX_ROOM_M = 8.0
#: baseline instruction types that only keep the driver on the road
FOLLOW_TYPES = frozenset({"start", "follow", "follow_distance", "follow_highway", "follow_highway_distance"})
#: connection directions of a turn
TURN_DIRECTIONS = {Intent.LEFT: frozenset("lL"), Intent.RIGHT: frozenset("rR")}


# ---------------------------------------------------------------------------------- timing
def _late_ok(view: RouteView, g: Group, params: DeliveryParams) -> bool:
    """Whether every late distance is later than the baseline's last instruction of ``g``, and
    that instruction reads as the maneuver (the text the family moves)."""
    last = view.baseline.instructions[g.index[-1]]
    return last.trigger < g.maneuver.pos - params.late_m[1] and _reads(last.rendered(), g.maneuver.intent)


def _early_trigger(view: RouteView, g: Group, e: float) -> float | None:
    """Where the early instruction of ``g`` starts (``e`` m before the junction before the
    maneuver's), or None when the route does not allow it (module docstring)."""
    m, instrs = g.maneuver, view.baseline.instructions
    before = [j for j in view.junctions if j.pos < m.pos - 0.5]
    if not before or before[-1].choice:
        return None
    jp = before[-1]
    prev = [p for p in view.maneuvers if p.pos < m.pos and not p.kind.startswith("lane_change")]
    floor = max(prev[-1].pos, prev[-1].end) + AFTER_EXIT_M if prev else 0.0
    if jp.pos <= floor or any(jp.pos == p.pos for p in view.maneuvers):
        return None
    t = max(jp.pos - e, floor)
    if any(p.kind.startswith("lane_change") and t <= p.pos < m.pos for p in view.maneuvers):
        return None
    earlier = [ins.trigger for ins in instrs if ins.trigger < t]
    if earlier:
        t = max(t, earlier[-1] + 1.0)
    if any(is_lane_change(ins) and t <= ins.trigger < m.pos for ins in instrs):
        return None
    if t > jp.pos - EARLY_BEFORE_M or t >= instrs[g.index[0]].trigger:
        return None
    return t


def timing_set(view: RouteView, k: int, seed: int, params: DeliveryParams) -> InstructionSet:
    """Variant ``k`` of ``timing``: late (even k), early where the route allows it (odd k)."""
    gs = [g for g in groups(view) if _late_ok(view, g, params)]
    if not gs:
        raise Unbuildable(f"no junction maneuver announced more than {params.late_m[1]:g} m before its "
                          "junction in words that read as it, so none can come later" if groups(view)
                          else "no junction maneuver")
    rng = variant_rng(Family.TIMING, seed, view.baseline.route_id, k)
    late = float(round(rng.uniform(*params.late_m), 1))
    early = float(round(rng.uniform(*params.early_m), 1))
    instrs = view.baseline.instructions
    changes: dict[int, list[Instruction]] = {}
    for g in gs:
        m, last = g.maneuver, instrs[g.index[-1]]
        t = _early_trigger(view, g, early) if k % 2 else None
        if t is None:
            drop, t, tag = g.index, m.pos - late, "late"
        else:
            drop, tag = tuple(i for i, ins in enumerate(instrs) if t <= ins.trigger < m.pos), "early"
        changes.update({i: [] for i in drop})
        changes[g.index[-1]] = [moved(last, t, last.text, tag, m.pos)]
    return assemble(view, Family.TIMING, k, seed, changes)


# -------------------------------------------------------------------------------- distance
def offers(net: RoadNet, j: JunctionPass, intent: Intent) -> bool:
    """Whether junction pass ``j`` offers a turn of ``intent`` from the edge the route enters
    it on (a choice, not on a roundabout's ring)."""
    if not j.choice or j.from_edge in net.roundabout_edges:
        return False
    dirs = {c.direction for to in net.successors.get(j.from_edge, ())
            for c in net.connections.get((j.from_edge, to), ())}
    return bool(dirs & TURN_DIRECTIONS[intent])


def ordinal(view: RouteView, m: Maneuver, trigger: float) -> int:
    """The turn ``m`` counted among the junctions from ``trigger`` to it that offer it (1:
    the first)."""
    return sum(1 for j in view.junctions if trigger <= j.pos <= m.pos + 0.01
               and (j.pos >= m.pos - 0.01 or offers(view.net, j, m.intent)))


def _pool(m: Maneuver) -> tuple[tuple[str, str], ...]:
    """The distance (and, for turns, ordinal) templates of a maneuver; () when none applies."""
    if m.kind in ("turn_left", "turn_right") and m.intent in TURN_DIRECTIONS:
        return DISTANCE_TURN + ORDINAL_TURN
    return {"straight": DISTANCE_STRAIGHT, "roundabout": DISTANCE_ROUNDABOUT,
            "highway_exit": DISTANCE_HIGHWAY_EXIT}.get(m.kind, ())


def _stretch(view: RouteView, g: Group) -> int:
    """The index of the first instruction that leads up to ``g``'s maneuver: the follow (and
    start) instructions right before its own, else its own first."""
    instrs, first = view.baseline.instructions, g.index[0]
    while first > 0 and instrs[first - 1].type in FOLLOW_TYPES:
        first -= 1
    return first


def ordinal_run(view: RouteView, gs: list[Group], gi: int) -> tuple[int, ...]:
    """The instructions an ordinal instruction for the turn ``gs[gi]`` replaces: its own, those
    of the straight crossings right before it (no lane change between; as many as keep the
    ordinal at the fourth or under: the instruction is held across them, which is what an
    ordinal asks) and the follow instructions that lead up to them."""
    instrs, m = view.baseline.instructions, gs[gi].maneuver
    start, n = _stretch(view, gs[gi]), 1
    for g in reversed(gs[:gi]):
        if g.maneuver.kind != "straight":
            break
        n += any(j.pos == g.maneuver.pos and offers(view.net, j, m.intent) for j in view.junctions)
        if n > len(ORDINALS):
            break
        first = _stretch(view, g)
        if not all(instrs[i].type in FOLLOW_TYPES or i in g.index for i in range(first, start)):
            break
        start = first
    return tuple(range(start, gs[gi].index[-1] + 1))


def _named(view: RouteView, m: Maneuver, ins: Instruction, tpl: tuple[str, str], k: int,
           trigger: float) -> Instruction:
    """``ins`` naming ``m`` from ``trigger`` with template ``tpl``: its distance from there, or
    its ordinal among the junctions from there that offer the turn (past the fourth: by
    distance, the template ``k`` picks)."""
    slots = {"dir": str(m.intent), "exit": ORDINALS[min(max(m.exit, 1), len(ORDINALS)) - 1]}
    tid, text = tpl
    if tid.startswith("o"):
        n = ordinal(view, m, trigger)
        if n <= len(ORDINALS):
            return moved(ins, trigger, fill(text, ord=ORDINALS[n - 1], **slots), tid, m.pos)
        tid, text = DISTANCE_TURN[k % len(DISTANCE_TURN)]
    return moved(ins, trigger, fill(text, **slots), tid, m.pos)


def distance_set(view: RouteView, k: int, seed: int, gs: list[Group],
                 perms: list[np.ndarray]) -> InstructionSet:
    """Variant ``k`` of ``distance`` over the maneuvers ``gs`` (each with its permutation): by
    distance, each of the maneuver's instructions names it from its trigger; by ordinal, one
    instruction names it from where the stretch that leads to it starts, held across the
    straight crossings before it (:func:`ordinal_run`)."""
    instrs = view.baseline.instructions
    changes: dict[int, list[Instruction]] = {}
    for gi, (g, perm) in enumerate(zip(gs, perms)):
        pool, m = _pool(g.maneuver), g.maneuver
        tpl = pool[int(perm[k % len(pool)])]
        if tpl[0].startswith("o"):
            run = ordinal_run(view, gs, gi)
            changes.update({i: [] for i in run})
            changes[g.index[0]] = [_named(view, m, instrs[g.index[0]], tpl, k, instrs[run[0]].trigger)]
        else:
            changes.update({i: [_named(view, m, instrs[i], tpl, k, instrs[i].trigger)] for i in g.index})
        for new in (ins for i in g.index for ins in changes[i]):
            assert_intent(new.rendered(), frozenset({m.intent}), "icrsumo/instructions/delivery_texts.py",
                          f"template {new.template}", "rephrase the template")
    return assemble(view, Family.DISTANCE, k, seed, changes)


# ------------------------------------------------------------------------------ correction
def _lower_first(text: str) -> str:
    """``text`` with its first letter lowercased when the word goes on in lower case."""
    return text[:1].lower() + text[1:] if text[1:2].islower() else text


def _fix_trigger(view: RouteView, g: Group, params: DeliveryParams) -> float | None:
    """Where the correction of ``g`` comes, or None when there is no room for it."""
    first = view.baseline.instructions[g.index[0]].trigger
    t = max(first + WRONG_M, g.maneuver.pos - params.correction_m)
    return t if t <= g.maneuver.pos - FIX_ROOM_M else None


def correction_groups(view: RouteView, banks: Banks, params: DeliveryParams) -> list[Group]:
    """The maneuvers that can be corrected: a misleading bank for their intent, room before
    the junction, a baseline text at the junction that reads as their intent."""
    instrs = view.baseline.instructions
    out = []
    for g in groups(view):
        tau = g.maneuver.intent
        if tau in banks.misleading and tau in CONTRADICTS and _fix_trigger(view, g, params) is not None \
                and _reads(instrs[g.index[-1]].rendered(), tau):
            out.append(g)
    return out


def _reads(text: str, tau: Intent) -> bool:
    return classify_intent(text) == tau


def correction_set(view: RouteView, k: int, seed: int, banks: Banks, params: DeliveryParams,
                   gs: list[Group], perms: list[np.ndarray]) -> InstructionSet:
    """Variant ``k`` of ``correction`` over the maneuvers ``gs`` (a permutation of the
    misleading entries and one of the opening phrases for each)."""
    instrs = view.baseline.instructions
    fresh = max((ins.id for ins in instrs), default=-1) + 1
    changes: dict[int, list[Instruction]] = {}
    for n, g in enumerate(gs):
        m, first, last = g.maneuver, instrs[g.index[0]], instrs[g.index[-1]]
        pool = banks.misleading[m.intent]["distance" if "[x]" in first.text else "plain"]
        entry = pool[int(perms[2 * n][k % len(pool)])]
        wrong = replace(first, text=fill(entry.text, first.junction), template=entry.id, source=first.text)
        assert_intent(wrong.rendered(), CONTRADICTS[m.intent], banks.folder / "misleading.json",
                      f"entry {entry.id}")
        pid, prefix = CORRECTION_PREFIXES[int(perms[2 * n + 1][k % len(CORRECTION_PREFIXES)])]
        t, iid = _fix_trigger(view, g, params), None if len(g.index) > 1 else fresh
        text = prefix + _lower_first(last.text) if prefix else last.text
        fix = moved(last, t, text, f"fix:{pid}", m.pos, iid)
        if not _reads(fix.rendered(), m.intent):  # the opening phrase hides it: the bare text
            fix = moved(last, t, last.text, "fix:bare", m.pos, iid)
        fresh += int(iid is not None)
        changes.update({i: [] for i in g.index})
        changes[g.index[0]] = [wrong, fix]
    return assemble(view, Family.CORRECTION, k, seed, changes)


# -------------------------------------------------------------------------------- dispatch
def delivery_variants(family: str, view: RouteView, ks: range, seed: int, banks: Banks,
                      params: DeliveryParams = DeliveryParams()) -> list[InstructionSet]:  # noqa: B008
    """Variants ``ks`` of delivery ``family`` on one route; :class:`Unbuildable` when the
    route has nothing the family can change."""
    rid = view.baseline.route_id
    if family == Family.TIMING:
        return [timing_set(view, k, seed, params) for k in ks]
    if family == Family.DISTANCE:
        gs = [g for g in groups(view) if _pool(g.maneuver)]
        if not gs:
            raise Unbuildable("no turn, straight crossing, roundabout or highway exit to name by distance")
        perms = permutations(family, seed, rid, [len(_pool(g.maneuver)) for g in gs])
        return [distance_set(view, k, seed, gs, perms) for k in ks]
    if family == Family.CORRECTION:
        gs = correction_groups(view, banks, params)
        if not gs:
            raise Unbuildable(f"no junction maneuver with room for a correction ({FIX_ROOM_M:g} m before "
                              f"its junction, {WRONG_M:g} m after its first instruction)" if groups(view)
                              else "no junction maneuver")
        sizes = [n for g in gs for n in (len(banks.misleading[g.maneuver.intent][
            "distance" if "[x]" in view.baseline.instructions[g.index[0]].text else "plain"]),
            len(CORRECTION_PREFIXES))]
        perms = permutations(family, seed, rid, sizes)
        return [correction_set(view, k, seed, banks, params, gs, perms) for k in ks]
    if family == Family.NOTICE:
        return [notice_set(view, k, seed, params) for k in ks]
    raise ValueError(f"not a delivery family: {family}")
