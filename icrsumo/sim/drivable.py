"""The drivable area of a road network as exact polygons (shapely), for the roadside check.

A point is drivable when it lies on a car lane or on a junction's carriageway:

* every lane a passenger car may use (normal and junction-internal lanes): its centre line
  widened by half the lane width to each side, flat at its ends, mitred at its bends (mitre
  limit 2, as the BEV raster draws lanes);
* every junction a car lane meets: the junction's own outline (netconvert's node shape),
  minus its walking areas (the pavement corners of junctions with sidewalks). Crossings stay
  drivable: they are painted on the carriageway.

Lane outlines are flat-capped, so on the outside of a kink between a lane and the next one
(a bend drawn as a short edge between two junctions, an internal lane leaving a road at an
angle) they leave wedges that no junction outline covers, where CARLA's road is continuous.
Each joint of a connection (a lane and the lane after it, :func:`joint_polygons`) is
therefore drawn as one mitred piece, and a 5 cm morphological closing (:data:`CLOSING_M`)
fills the slivers that remain. A point then counts as drivable within :data:`TOLERANCE_M`
of the area: a 4.9 m car off-tracking on a 4 m lane cuts the inner edge of a tight bend by
a few centimetres.

The test is a point-in-polygon predicate on prepared geometry (boundary points count as
drivable), independent of any raster resolution or channel layout.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from functools import lru_cache

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon
from shapely.ops import substring

from icrsumo.world.networks import RoadNet

#: mitre limit of the lane outlines (a bend's outer corner reaches at most 2 half-widths out)
MITRE_LIMIT = 2.0
#: m of the closing (grow, then shrink) that fills the slivers between lane outlines
CLOSING_M = 0.05
#: m beyond the closed area within which a point still counts as drivable
TOLERANCE_M = 0.1


#: side (m) of the cells that memoise the test: a cell wholly inside or wholly outside the
#: area answers for every point in it; only points in cells the boundary crosses are tested
CELL_M = 0.5
#: the cells are tested grown by this much (m), so float rounding of a point's cell index
#: cannot put it outside the box that was tested
_CELL_PAD = 1e-6


def polygonal(geom):
    """The polygons of ``geom`` (make_valid and unions may add stray lines and points)."""
    parts = [g for g in shapely.get_parts(geom) if g.geom_type in ("Polygon", "MultiPolygon")]
    return shapely.union_all(parts) if parts else Polygon()


class DrivableArea:
    """The drivable area of one network (see the module docstring); ``geometry`` is a shapely
    (Multi)Polygon in SUMO coordinates (m). Answers are exact point-in-polygon results; cells
    of :data:`CELL_M` that lie wholly inside or outside are remembered, so most points cost a
    dictionary lookup."""

    def __init__(self, geometry) -> None:
        self.geometry = geometry
        shapely.prepare(self.geometry)
        self._cells: dict[tuple[int, int], int] = {}  # 0 outside, 1 inside, 2 crossed by the boundary

    def _cell(self, key: tuple[int, int]) -> int:
        x0, y0 = key[0] * CELL_M - _CELL_PAD, key[1] * CELL_M - _CELL_PAD
        box = shapely.box(x0, y0, x0 + CELL_M + 2 * _CELL_PAD, y0 + CELL_M + 2 * _CELL_PAD)
        if shapely.contains(self.geometry, box):
            got = 1
        elif not shapely.intersects(self.geometry, box):
            got = 0
        else:
            got = 2
        self._cells[key] = got
        return got

    @classmethod
    def from_net(cls, net: RoadNet) -> DrivableArea:
        lanes = lane_polygons(net)
        joints = joint_polygons(net)
        return cls(close_and_widen(polygonal(shapely.union_all([*lanes, *joints, carriageway(net)]))))

    def contains(self, x: float, y: float) -> bool:
        """Whether the point (x, y) m is drivable (a non-finite point is not)."""
        try:
            key = (math.floor(x / CELL_M), math.floor(y / CELL_M))
        except (ValueError, OverflowError):  # NaN, inf
            return False
        got = self._cells.get(key)
        if got is None:
            got = self._cell(key)
        if got != 2:
            return got == 1
        return bool(shapely.intersects_xy(self.geometry, x, y))

    def contains_xy(self, xy: np.ndarray) -> np.ndarray:
        """:meth:`contains` of points (N, 2) m, as an (N,) bool array (the plain predicate)."""
        pts = np.asarray(xy, dtype=float).reshape(-1, 2)
        out = np.zeros(len(pts), dtype=bool)
        finite = np.isfinite(pts).all(axis=1)
        if finite.any():
            out[finite] = shapely.intersects_xy(self.geometry, pts[finite, 0], pts[finite, 1])
        return out

    def count_off(self, points: Iterable[tuple[float, float]]) -> int:
        """How many of ``points`` ((x, y) m each) are off the drivable area."""
        contains = self.contains
        return sum(1 for x, y in points if not contains(x, y))


def carriageway(net: RoadNet):
    """The junctions' carriageway: every junction outline a car lane meets (netconvert's node
    shapes), minus the walking areas (shapely polygons, m)."""
    sn = net.sumolib_net
    car_nodes = set()
    for eid in net.passenger_lanes:
        edge = sn.getEdge(eid)
        car_nodes.update((edge.getFromNode().getID(), edge.getToNode().getID()))
    junctions = []
    for nid in sorted(car_nodes):
        shape = sn.getNode(nid).getShape()
        if len(shape) >= 3:
            junctions.append(polygonal(shapely.make_valid(Polygon([p[:2] for p in shape]))))
    walking = []
    for edge in sn.getEdges(withInternal=True):
        if edge.getFunction() == "walkingarea":
            for lane in edge.getLanes():
                shape = lane.getShape()
                if len(shape) >= 3:
                    walking.append(polygonal(shapely.make_valid(Polygon([p[:2] for p in shape]))))
    return shapely.difference(shapely.union_all(junctions), shapely.union_all(walking))


def close_and_widen(area, closing: float = CLOSING_M, tolerance: float = TOLERANCE_M):
    """``area`` (shapely polygons, m) closed by ``closing`` m (gaps narrower than twice that
    filled, outlines otherwise kept) and then grown by ``tolerance`` m."""
    closed = polygonal(area.buffer(closing, join_style="mitre").buffer(-closing, join_style="mitre"))
    return polygonal(closed.buffer(tolerance, join_style="mitre")) if tolerance > 0 else closed


def lane_polygons(net: RoadNet) -> list:
    """Every passenger lane's outline: its centre line widened by half its width to each side,
    flat at the ends, mitred at the bends (shapely Polygons, sorted by lane id)."""
    sn = net.sumolib_net
    return [LineString(net.lane_shape[lid]).buffer(float(sn.getLane(lid).getWidth()) / 2.0, cap_style="flat",
                                                   join_style="mitre", mitre_limit=MITRE_LIMIT)
            for lid in sorted(net.lane_shape) if len(net.lane_shape[lid]) >= 2]


#: m of each lane on either side of a joint that its joint piece covers
JOINT_M = 3.0


def joint_polygons(net: RoadNet) -> list:
    """One outline per joint of every passenger connection (incoming lane, its internal lanes,
    outgoing lane: each lane and the next): the last :data:`JOINT_M` m of the one and the first
    of the other as one polyline, widened by half the narrower lane's width, mitred at the
    joint as a lane's bend is (shapely Polygons, in a fixed order)."""
    sn = net.sumolib_net
    width = {}
    out = []
    seen = set()
    for key in sorted(net.connections):
        for c in net.connections[key]:
            chain = [f"{c.from_edge}_{c.from_lane}", *c.via_chain, f"{c.to_edge}_{c.to_lane}"]
            for a, b in zip(chain, chain[1:]):
                if (a, b) in seen or a not in net.lane_shape or b not in net.lane_shape:
                    continue
                seen.add((a, b))
                # along the drawn shapes (a lane's length attribute may differ from its shape's)
                sa, sb = LineString(net.lane_shape[a]), LineString(net.lane_shape[b])
                tail = substring(sa, max(0.0, sa.length - JOINT_M), sa.length)
                head = substring(sb, 0.0, min(sb.length, JOINT_M))
                pts = np.concatenate([np.asarray(tail.coords), np.asarray(head.coords)])[:, :2]
                keep = np.concatenate([[True], np.hypot(*np.diff(pts, axis=0).T) > 1e-3])
                pts = pts[keep]
                if len(pts) < 2:
                    continue
                for lane in (a, b):
                    if lane not in width:
                        width[lane] = float(sn.getLane(lane).getWidth())
                half = 0.5 * min(width[a], width[b])
                out.append(LineString(pts).buffer(half, cap_style="flat", join_style="mitre",
                                                  mitre_limit=MITRE_LIMIT))
    return out


@lru_cache(maxsize=16)
def drivable_area(net: RoadNet) -> DrivableArea:
    """The :class:`DrivableArea` of ``net`` (built once per network and process)."""
    return DrivableArea.from_net(net)
