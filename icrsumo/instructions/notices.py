"""The ``notice`` family: LangAuto-style notices between the navigation instructions, which
stay the baseline's.

A variant keeps the baseline's notices as they are and adds notices where the route has the
thing they name, read from the network: traffic lights and stop signs (the junction's type),
pedestrians (a junction with crossings), merging traffic (a junction where the route has no
choice and another road joins the edge it takes, or a highway entry). Each junction of the
route with one of them gets one notice of a type drawn among its own, from ``lead`` metres
before the junction entry (drawn per notice in :attr:`DeliveryParams.notice_lead_m`) until it
is left (its exit, at least :data:`~icrsumo.instructions.baseline.AFTER_M` past the entry). A
notice never overlaps another (the baseline's are shown exactly as in the baseline): its start
moves past a notice that ends at least :data:`MIN_LEAD_M` before its junction; otherwise it is
left out. Then one caution notice (cyclists, road works, ...: things the network does not
place) of :data:`CAUTION_M` m goes on a stretch free of notices, drawn among them. Texts come
from :data:`~icrsumo.instructions.delivery_texts.NOTICE_TEXTS`; every one classifies as a
caution (stop or unknown), never a maneuver.
"""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

from icrsumo.core.types import InstructionSet, Intent, JunctionPass, Notice
from icrsumo.core.vocab import Family
from icrsumo.world.networks import RoadNet

from .baseline import AFTER_M
from .delivery_common import DeliveryParams, RouteView, Unbuildable, assemble, variant_rng
from .delivery_texts import NOTICE_TEXTS
from .families import assert_intent
from .maneuvers import junction_exit

#: a notice starts at least this far (m) before its junction
MIN_LEAD_M = 10.0
#: length (m) of a caution notice
CAUTION_M = 30.0
#: what a notice may classify as: a caution, never a maneuver
NOTICE_INTENTS = frozenset({Intent.STOP, Intent.UNKNOWN})


@lru_cache(maxsize=8)
def _incoming(net: RoadNet) -> dict[str, int]:
    """Edge -> how many edges lead into it."""
    count: dict[str, int] = {}
    for succ in net.successors.values():
        for to in succ:
            count[to] = count.get(to, 0) + 1
    return count


def site_types(view: RouteView, j: JunctionPass) -> tuple[str, ...]:
    """The notice types junction pass ``j`` can carry (() for none)."""
    net = view.net
    ntype = net.node_type.get(j.junction, "")
    merge = (not j.choice and _incoming(net).get(j.to_edge, 0) >= 2) or any(
        m.kind == "highway_enter" and m.pos == j.pos for m in view.maneuvers)
    return tuple(t for t, ok in (("notice_traffic_light", ntype.startswith("traffic_light")),
                                 ("notice_stop_sign", ntype in ("priority_stop", "allway_stop")),
                                 ("notice_pedestrians", j.junction in net.crossing_nodes),
                                 ("notice_merging", merge)) if ok)


def fit(start: float, end: float, pos: float, busy: list[tuple[float, float]]) -> tuple[float, float] | None:
    """The window [start, end) of a notice for a junction at ``pos`` moved past the ``busy``
    windows that end :data:`MIN_LEAD_M` or more before ``pos``; None when another overlaps it
    or too little is left before ``pos``."""
    for a, b in sorted(busy):
        if a < end and b > start:
            if b > pos - MIN_LEAD_M:
                return None
            start = b
    return (start, end) if pos - start >= MIN_LEAD_M else None


def free_stretches(busy: list[tuple[float, float]], length: float) -> list[tuple[float, float]]:
    """The stretches of [0, ``length``] that no ``busy`` window covers, :data:`CAUTION_M` or longer."""
    out, at = [], 0.0
    for a, b in sorted(busy):
        if a - at >= CAUTION_M:
            out.append((at, a))
        at = max(at, b)
    if length - at >= CAUTION_M:
        out.append((at, length))
    return out


def _text(ntype: str, u: int) -> str:
    tid, text = NOTICE_TEXTS[ntype][u % len(NOTICE_TEXTS[ntype])]
    assert_intent(text, NOTICE_INTENTS, "icrsumo/instructions/delivery_texts.py", f"notice {tid}",
                  "rephrase the notice")
    return text


def notice_set(view: RouteView, k: int, seed: int, params: DeliveryParams) -> InstructionSet:
    """Variant ``k`` of ``notice`` (module docstring); :class:`Unbuildable` when no notice fits."""
    rng = variant_rng(Family.NOTICE, seed, view.baseline.route_id, k)
    base = view.baseline.notices
    busy = [(n.trigger, n.end) for n in base]
    added: list[Notice] = []

    def add(start: float, end: float, text: str, ntype: str) -> None:
        added.append(Notice(id=len(base) + len(added), trigger=round(start, 2), end=round(end, 2),
                            text=text, type=ntype, intent=Intent.STOP))
        busy.append((start, end))

    for j in view.junctions:
        types = site_types(view, j)
        if not types:
            continue
        ntype = types[int(rng.integers(len(types)))]
        lead, u = float(rng.uniform(*params.notice_lead_m)), int(rng.integers(1 << 16))
        window = fit(max(0.0, j.pos - lead), max(j.pos + AFTER_M, junction_exit(view.net, j)), j.pos, busy)
        if window is not None:
            add(*window, _text(ntype, u), ntype)
    free = free_stretches(busy, view.length - AFTER_M)
    pick, where, u = int(rng.integers(1 << 16)), float(rng.random()), int(rng.integers(1 << 16))
    if free:
        a, b = free[pick % len(free)]
        start = a + where * (b - a - CAUTION_M)
        add(start, start + CAUTION_M, _text("notice_caution", u), "notice_caution")
    if not added:
        raise Unbuildable(f"no junction with lights, a stop sign, a crossing or merging traffic free of the "
                          f"baseline's notices, and no {CAUTION_M:g} m without one")
    return replace(assemble(view, Family.NOTICE, k, seed, {}),
                   notices=tuple(sorted((*base, *added), key=lambda n: n.trigger)))
