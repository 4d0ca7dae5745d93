"""How far SUMO must look for lanes when the ego is moved, cell by cell: the narrowest lane search
that provably picks the lane SUMO's full search picks. Pure (numpy); no SUMO.

The loop moves the ego every step with ``moveToXY(keepRoute=2)`` and SUMO's default search radius
(``FULL_RADIUS``, 100 m). SUMO (``Helper::moveToXYMap`` in ``src/libsumo/Helper.cpp``, SUMO 1.28)
takes every lane of every edge that has a lane within the radius as a candidate and ranks it by

    value = 0.5 * distN + 0.35 * angleN + 1 * idN + 0.1 * onRouteN + 0.1 * sameEdgeN

with ``distN = 1 - dist / maxDist`` (``-10`` where the mapping is ambiguous: the position lies
past an end of the lane), ``maxDist`` the largest ``min(dist, 3.2)`` over the candidates, every
other term in [0, 1] and ``idN`` 0 here (it matches a lane whose id is ``"_-1"``; the grid is
not used on a network that has one). The first best lane in SUMO's lane order wins. What the
search radius changes is only the candidate set. A narrower radius ``r`` gives the same lane
wherever, for the point moved to,

* (A) a candidate lane lies at a distance in [3.2, r]: ``maxDist`` is 3.2 with either radius;
* (B) a candidate lane lies nearer than ``r - 3.52`` (and 31.68) m with its nearest point
  inside it (not an end): its value exceeds every value a lane beyond ``r`` can reach
  (``1.05 - r / 6.4`` unambiguous, ``-4.45`` ambiguous), so the best lane is within ``r`` and,
  being unambiguous, keeps SUMO's tie order.

:class:`MatchGrid` checks both on a grid of ``CELL`` m cells for every point of a cell at once
(a lane's least distance over the cell exactly, its largest bounded; a 1 cm margin), for each of
``RADII``, tile by tile as the ego comes near, and :meth:`MatchGrid.radius` gives the narrowest
radius that holds at a point
(``FULL_RADIUS`` where none does: off the roads, at a lane's end with nothing beside it). Every
lane the proof names is a candidate SUMO sees: a lane a passenger car may use with a shape of
non-zero length (``RoadNet.lane_shape``: normal and junction-internal lanes).
"""

from __future__ import annotations

import numpy as np

from icrsumo.world.networks import RoadNet

#: SUMO's own search radius (m): the episodes are defined by it
FULL_RADIUS = 100.0
#: narrower radii (m) tried, narrowest first
RADII = (8.0, 12.0, 20.0)
#: SUMO_const_laneWidth (m): the cap of the distance normaliser
LANE_WIDTH = 3.2
#: side (m) of a grid cell
CELL = 1.0
#: margin (m) on every inequality: SUMO's distances are doubles computed another way
EPS = 0.01
#: the unused lane id that would score ``idN`` = 1 (``moveToXY`` with edge "" and lane -1)
_ORIG_ID = "_-1"


#: side (cells) of the square tiles the grid is computed in, each when first needed
TILE = 32


class MatchGrid:
    """Per cell of a grid over the network (origin ``x0``, ``y0`` m; ``cell`` m), the narrowest
    of ``radii`` whose lane search picks SUMO's lane (:meth:`radius`). The cells are computed
    tile by tile (``TILE`` cells a side) when the ego first comes near: a drive visits a small
    part of a town. ``lanes``: the candidate lanes' shapes ((N, 2) m each); ``enabled`` False
    (a lane named or parameterised ``"_-1"``): always ``FULL_RADIUS``."""

    def __init__(self, lanes: list[np.ndarray], radii: tuple[float, ...] = RADII, cell: float = CELL,
                 enabled: bool = True) -> None:
        shapes = [np.asarray(s, dtype=float)[:, :2] for s in lanes if len(s) >= 2]
        self.shapes = [s for s in shapes if float(np.hypot(*np.diff(s, axis=0).T).sum()) > 0.0]
        self.radii, self.cell = tuple(radii), float(cell)
        self.enabled = enabled and bool(self.shapes)
        self.margin = max(self.radii) + self.cell
        if self.shapes:
            self._lo = np.array([s.min(axis=0) for s in self.shapes]) - self.margin
            self._hi = np.array([s.max(axis=0) for s in self.shapes]) + self.margin
            lo = self._lo.min(axis=0)
            self.x0, self.y0 = float(np.floor(lo[0])), float(np.floor(lo[1]))
        else:
            self.x0 = self.y0 = 0.0
        self._tiles: dict[tuple[int, int], np.ndarray] = {}

    def radius(self, x: float, y: float) -> float:
        """The search radius (m) for moving the ego's front bumper to (x, y) m."""
        if not self.enabled:
            return FULL_RADIUS
        i = int((y - self.y0) // self.cell)
        j = int((x - self.x0) // self.cell)
        key = (i // TILE, j // TILE)
        codes = self._tiles.get(key)
        if codes is None:
            codes = self._tiles[key] = self.codes(key[0] * TILE, key[1] * TILE, TILE, TILE)
        k = codes[i % TILE, j % TILE]
        return self.radii[k] if k < len(self.radii) else FULL_RADIUS

    def codes(self, i0: int, j0: int, ny: int, nx: int) -> np.ndarray:
        """(ny, nx) uint8: for the cells from row ``i0``, column ``j0``, the index into
        ``radii`` of the narrowest radius that holds (``len(radii)``: none)."""
        cell, x0, y0, k_full = self.cell, self.x0, self.y0, len(self.radii)
        out = np.full((ny, nx), k_full, np.uint8)
        if not self.enabled:
            return out
        bx = (x0 + j0 * cell, x0 + (j0 + nx) * cell)
        by = (y0 + i0 * cell, y0 + (i0 + ny) * cell)
        hit = ((self._lo[:, 0] <= bx[1]) & (self._hi[:, 0] >= bx[0])
               & (self._lo[:, 1] <= by[1]) & (self._hi[:, 1] >= by[0]))
        near = np.zeros((k_full, ny, nx), bool)     # (A): a lane in [3.2, r] m
        inside = np.zeros((k_full, ny, nx), bool)   # (B): an unambiguous lane nearer than r - 3.52
        for n in np.flatnonzero(hit):
            _lane(self, n, i0, j0, ny, nx, near, inside)
        for k in range(k_full - 1, -1, -1):
            out[near[k] & inside[k]] = k
        return out

    @property
    def extent(self) -> tuple[int, int]:
        """(rows, columns) of cells that cover every lane with the search margin."""
        hi = self._hi.max(axis=0)
        return int((hi[1] - self.y0) // self.cell) + 1, int((hi[0] - self.x0) // self.cell) + 1

    def share(self) -> dict[float, float]:
        """Share of the network's cells per radius (FULL_RADIUS included), all tiles computed
        (for tests and reports)."""
        if not self.shapes:
            return {FULL_RADIUS: 1.0}
        codes = self.codes(0, 0, *self.extent)
        out = {r: float(np.count_nonzero(codes == k)) / codes.size for k, r in enumerate(self.radii)}
        out[FULL_RADIUS] = float(np.count_nonzero(codes >= len(self.radii))) / codes.size
        return out


def _seg_dist(px: np.ndarray, py: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance (m) from points (px, py) to the segment a-b."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    l2 = dx * dx + dy * dy
    if l2 <= 0.0:
        return np.hypot(px - a[0], py - a[1])
    t = np.clip(((px - a[0]) * dx + (py - a[1]) * dy) / l2, 0.0, 1.0)
    return np.hypot(px - (a[0] + t * dx), py - (a[1] + t * dy))


def _rect_dist(px: float, py: float, cx: np.ndarray, cy: np.ndarray, half: float) -> np.ndarray:
    """Distance (m) from the point (px, py) to the squares of centres (cx, cy), side 2 * half."""
    return np.hypot(np.maximum(np.abs(px - cx) - half, 0.0), np.maximum(np.abs(py - cy) - half, 0.0))


def _span(lo: float, hi: float, origin: float, cell: float, first: int, end: int, extra: int = 1
          ) -> tuple[int, int]:
    """Grid indices [a, b) of the cells from ``lo`` to ``hi`` m (``extra`` more at the end),
    within [first, end)."""
    return max(int((lo - origin) // cell), first), min(int((hi - origin) // cell) + extra, end)


def _lane(g: MatchGrid, n: int, gi0: int, gj0: int, ny: int, nx: int,
          near: np.ndarray, inside: np.ndarray) -> None:
    """Mark in ``near`` and ``inside`` ((len(radii), ny, nx), the cells from row ``gi0``,
    column ``gj0``) where lane ``n`` of ``g`` satisfies (A) and (B).

    Per cell: the lane's least distance over the cell, exact where the lane does not cross it
    (the nearest of the cell's corners to the lane and of the lane's vertices to the cell), and
    a bound on its largest (the farthest corner + half the diagonal)."""
    s, cell, x0, y0, margin = g.shapes[n], g.cell, g.x0, g.y0, g.margin
    half, spread = 0.5 * cell, cell * np.sqrt(0.5)
    slo, shi = g._lo[n], g._hi[n]                  # the lane's box with the search margin
    j0, j1 = _span(slo[0], shi[0], x0, cell, gj0, gj0 + nx)
    i0, i1 = _span(slo[1], shi[1], y0, cell, gi0, gi0 + ny)
    if j0 >= j1 or i0 >= i1:
        return
    dv = np.full((i1 - i0 + 1, j1 - j0 + 1), np.inf)      # at the cells' corners
    for a, b in zip(s[:-1], s[1:], strict=True):
        wlo, whi = np.minimum(a, b) - margin, np.maximum(a, b) + margin
        wj0, wj1 = _span(wlo[0], whi[0], x0, cell, j0, j1 + 1, 2)
        wi0, wi1 = _span(wlo[1], whi[1], y0, cell, i0, i1 + 1, 2)
        if wj0 >= wj1 or wi0 >= wi1:
            continue
        px = x0 + np.arange(wj0, wj1) * cell
        py = y0 + np.arange(wi0, wi1) * cell
        sub = dv[wi0 - i0:wi1 - i0, wj0 - j0:wj1 - j0]
        np.minimum(sub, _seg_dist(px[None, :], py[:, None], a, b), out=sub)
    corners = (dv[:-1, :-1], dv[:-1, 1:], dv[1:, :-1], dv[1:, 1:])
    dmin = np.minimum(np.minimum(corners[0], corners[1]), np.minimum(corners[2], corners[3]))
    dmax = np.maximum(np.maximum(corners[0], corners[1]), np.maximum(corners[2], corners[3])) + spread
    reach = LANE_WIDTH + cell + 1.0                 # a vertex matters to the least distance only so near
    for vx, vy in s:
        wj0, wj1 = _span(vx - reach, vx + reach, x0, cell, j0, j1)
        wi0, wi1 = _span(vy - reach, vy + reach, y0, cell, i0, i1)
        if wj0 >= wj1 or wi0 >= wi1:
            continue
        cx = x0 + (np.arange(wj0, wj1) + 0.5) * cell
        cy = y0 + (np.arange(wi0, wi1) + 0.5) * cell
        sub = dmin[wi0 - i0:wi1 - i0, wj0 - j0:wj1 - j0]
        np.minimum(sub, _rect_dist(vx, vy, cx[None, :], cy[:, None], half), out=sub)
    cx = x0 + (np.arange(j0, j1) + 0.5) * cell
    cy = y0 + (np.arange(i0, i1) + 0.5) * cell
    ends = np.minimum(_rect_dist(s[0, 0], s[0, 1], cx[None, :], cy[:, None], half),
                      _rect_dist(s[-1, 0], s[-1, 1], cx[None, :], cy[:, None], half))
    interior = ends > dmax + EPS
    ri, rj = slice(i0 - gi0, i1 - gi0), slice(j0 - gj0, j1 - gj0)
    for k, r in enumerate(g.radii):
        near[k, ri, rj] |= (dmin >= LANE_WIDTH + EPS) & (dmax <= r - EPS)
        inside[k, ri, rj] |= interior & (dmax < min(r - 3.52, 31.68) - EPS)


def build_match_grid(lanes: dict[str, np.ndarray], orig_ids: frozenset[str] = frozenset(),
                     radii: tuple[float, ...] = RADII, cell: float = CELL) -> MatchGrid:
    """The grid for candidate lanes ``lanes`` (id -> (N, 2) shape, m); ``orig_ids``: the
    lanes' ``origId`` parameters (a lane id or parameter equal to ``"_-1"`` disables it)."""
    return MatchGrid(list(lanes.values()), radii, cell,
                     enabled=_ORIG_ID not in lanes and _ORIG_ID not in orig_ids)


_GRIDS: dict[str, MatchGrid] = {}


def match_grid(net: RoadNet) -> MatchGrid:
    """The :class:`MatchGrid` of ``net`` (one per process and network content)."""
    grid = _GRIDS.get(net.sha256)
    if grid is None:
        sl = net.sumolib_net
        orig = frozenset(str(sl.getLane(lid).getParam("origId", lid)) for lid in net.lane_shape)
        grid = _GRIDS[net.sha256] = build_match_grid(net.lane_shape, orig)
    return grid
