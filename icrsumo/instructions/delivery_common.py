"""What the delivery families (:mod:`.delivery`, :mod:`.notices`) share: their parameters,
the view of a route they read, its junction maneuvers with their baseline instructions, and
how a variant is assembled from the baseline."""

from __future__ import annotations

import zlib
from dataclasses import asdict, dataclass, replace

import numpy as np

from icrsumo.core.errors import Field, InputError
from icrsumo.core.types import Instruction, InstructionSet, JunctionPass, Maneuver
from icrsumo.core.vocab import Family
from icrsumo.world.networks import RoadNet

#: second seed word of each delivery family's Generators ("TIME", "DIST", "CORR", "NOTI")
STREAMS: dict[str, int] = {Family.TIMING: 0x54494D45, Family.DISTANCE: 0x44495354,
                           Family.CORRECTION: 0x434F5252, Family.NOTICE: 0x4E4F5449}
#: what this module accepts where the delivery families' parameters are named
_WHAT = Field("delivery")


@dataclass(frozen=True)
class DeliveryParams:
    """The delivery families' parameters (m): ``late_m`` (lo, hi) before the junction entry
    for a late instruction (drawn per variant, 1 to 30 m); ``early_m`` (lo, hi) before the
    junction it is held across for an early one (1 to 100 m); ``correction_m``: where a
    correction comes, before the junction entry (10 to 100 m); ``notice_lead_m`` (lo, hi):
    where a notice starts, before its junction (10 to 150 m)."""

    late_m: tuple[float, float] = (5.0, 15.0)
    early_m: tuple[float, float] = (10.0, 30.0)
    correction_m: float = 20.0
    notice_lead_m: tuple[float, float] = (30.0, 60.0)

    def check(self) -> None:
        """An InputError naming the first parameter out of its range."""
        for name, (lo, hi) in (("late_m", (1.0, 30.0)), ("early_m", (1.0, 100.0)),
                               ("notice_lead_m", (10.0, 150.0))):
            a, b = getattr(self, name)
            if not lo <= a <= b <= hi:
                raise InputError(_WHAT, name, f"({a:g}, {b:g}) is out of range",
                                 f"give (lo, hi) with {lo:g} <= lo <= hi <= {hi:g} (metres)")
        if not 10.0 <= self.correction_m <= 100.0:
            raise InputError(_WHAT, "correction_m", f"{self.correction_m:g} is out of range",
                             "give 10 to 100 (metres)")

    def to_dict(self) -> dict[str, object]:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


class Unbuildable(Exception):
    """A delivery family that cannot be built for a route; ``str()`` says why."""


@dataclass(frozen=True)
class RouteView:
    """What the delivery families read of one route: its baseline sequence, maneuvers
    (sorted), the junctions it passes, its network and length (m)."""

    baseline: InstructionSet
    maneuvers: tuple[Maneuver, ...]
    junctions: tuple[JunctionPass, ...]
    net: RoadNet
    length: float


@dataclass(frozen=True)
class Group:
    """A junction maneuver and the indices of its baseline instructions (trigger order)."""

    maneuver: Maneuver
    index: tuple[int, ...]


def navigator_metres(d: float) -> float:
    """A distance (m) as a navigator says it: to 10 m under 100 m (10 at least), to 50 m under
    500 m, else to 100 m."""
    step = 10 if d < 95 else 50 if d < 475 else 100
    return float(max(10, int(round(d / step)) * step))


def is_lane_change(ins: Instruction) -> bool:
    return ins.type.startswith("lane_change")


def groups(view: RouteView) -> list[Group]:
    """The junction maneuvers (not lane changes) that have baseline instructions, in route order."""
    out = []
    for m in view.maneuvers:
        if m.kind.startswith("lane_change") or m.kind == "follow":
            continue
        idx = tuple(i for i, ins in enumerate(view.baseline.instructions)
                    if ins.maneuver_pos == round(m.pos, 2) and not is_lane_change(ins))
        if idx:
            out.append(Group(m, idx))
    return out


def keep(ins: Instruction) -> Instruction:
    """A baseline instruction as a variant keeps it."""
    return replace(ins, template="keep", source=ins.text)


def moved(ins: Instruction, trigger: float, text: str, template: str, pos: float,
          iid: int | None = None) -> Instruction:
    """``ins`` (of a maneuver at route position ``pos``) with ``text`` from ``trigger``; a
    ``[x]`` in the text is the distance from there to the junction."""
    return replace(ins, id=ins.id if iid is None else iid, trigger=round(trigger, 2), text=text,
                   distance=navigator_metres(pos - trigger) if "[x]" in text else None,
                   template=template, source=ins.text)


def variant_rng(family: str, seed: int, route_id: str, k: int) -> np.random.Generator:
    """The Generator of variant ``k`` of a delivery family on one route."""
    return np.random.default_rng([seed, zlib.crc32(route_id.encode("utf-8")), STREAMS[family], k])


def permutations(family: str, seed: int, route_id: str, sizes: list[int]) -> list[np.ndarray]:
    """One permutation per pool size (per maneuver, in route order), the same for every K."""
    rng = np.random.default_rng([seed, zlib.crc32(route_id.encode("utf-8")), STREAMS[family]])
    return [rng.permutation(n) for n in sizes]


def assemble(view: RouteView, family: str, k: int, seed: int,
             changes: dict[int, list[Instruction]]) -> InstructionSet:
    """The variant: baseline instruction ``i`` replaced by ``changes[i]`` (empty: dropped),
    the others kept, in trigger order; triggers strictly increase."""
    out: list[Instruction] = []
    for i, ins in enumerate(view.baseline.instructions):
        out += changes[i] if i in changes else [keep(ins)]
    out.sort(key=lambda ins: ins.trigger)
    if any(a.trigger >= b.trigger for a, b in zip(out, out[1:])):  # the builders prevent it
        raise Unbuildable("two of its instructions would start at the same place")
    return InstructionSet(route_id=view.baseline.route_id, family=family, k=k, seed=seed,
                          instructions=tuple(out), notices=view.baseline.notices)
