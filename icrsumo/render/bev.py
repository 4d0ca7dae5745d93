"""Bird's-eye-view (BEV) rasterisation of a SUMO scene (:mod:`icrsumo.render`, the only cv2 user).

The raster an agent sees is a ``(C, H, W)`` uint8 array (values 0 or 255), one binary channel per
entry of :data:`CHANNELS`, in the ego's frame:

* the ego's centre is at pixel ``(row_ego, col_ego) = (height - behind_m / m_per_px, width / 2)``,
  its heading points up (towards row 0, the farthest ahead), its left is to the left (smaller
  column); the image is not mirrored;
* a world point ``p`` (SUMO coordinates, metres) and an ego pose ``(x, y, yaw)`` (yaw in radians
  counter-clockwise from +x) map to::

      dx, dy  = p - (x, y)
      forward =  dx * cos(yaw) + dy * sin(yaw)         # m ahead of the ego centre
      left    = -dx * sin(yaw) + dy * cos(yaw)         # m to the ego's left
      row     = row_ego - forward / m_per_px
      col     = col_ego - left / m_per_px

  with integer ``(row, col)`` the pixel centres (the convention of cv2's drawing and warping).

Static layers (drivable area, lane markings, stop-sign stop lines) are drawn once per network
into one world-aligned ``(H_net, W_net, 3)`` canvas at ``m_per_px``; each step crops and rotates
it with a single ``cv2.warpAffine`` and draws the dynamic things (vehicles, pedestrians, the ego,
traffic-light stop lines) straight into the ego frame. The route is never drawn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from icrsumo.world.networks import EGO_VCLASS, RoadNet

#: raster channels, in order
CHANNELS = ("drivable", "markings", "vehicles", "pedestrians", "ego", "stop", "go")
_DRIVABLE, _MARKINGS, _VEHICLES, _PEDESTRIANS, _EGO, _STOP, _GO = range(len(CHANNELS))
#: the channels drawn from the static canvas, in its order
_STATIC = np.array([_DRIVABLE, _MARKINGS, _STOP])

#: fixed-point bits for cv2 drawing (sub-pixel accurate polygons and lines)
_SHIFT = 4
_ONE = 1 << _SHIFT
#: margin (m) around the network's lanes in the static canvas
_MARGIN_M = 10.0
#: stop-line thickness (m, at least 1 px)
STOP_LINE_M = 1.0
#: pedestrian footprint: square of this side (m, at least 2 px)
PEDESTRIAN_M = 0.8
#: SUMO link directions ordered from the left of a lane to its right (stop-line sub-segments)
_DIR_ORDER = {"t": 0, "l": 1, "L": 2, "s": 3, "R": 4, "r": 5}
#: connection states that oblige a stop at stop-sign junctions (minor stop, all-way stop)
_STOP_SIGN_STATES = frozenset("sw")
_STOP_SIGN_NODES = frozenset({"priority_stop", "allway_stop"})
#: rectangle corners in units of half length / half width, in convex order
_CORNER_L = np.array([1.0, 1.0, -1.0, -1.0])
_CORNER_W = np.array([1.0, -1.0, -1.0, 1.0])

# traffic-light state character -> 0 nothing, 1 stop, 2 go
_TL_CLASS = np.zeros(256, dtype=np.uint8)
for _c in "rRyYs":
    _TL_CLASS[ord(_c)] = 1
for _c in "gG":
    _TL_CLASS[ord(_c)] = 2


@dataclass(frozen=True)
class BevSpec:
    """Geometry of the BEV raster.

    ``m_per_px``: resolution (m per pixel); ``height`` x ``width``: raster size (px);
    ``behind_m``: view behind the ego centre (m). The view ahead is
    ``height * m_per_px - behind_m`` (48 m by default), ``width * m_per_px / 2`` to each side.
    ``channels``: the raster's channels, a subset of :data:`CHANNELS` in any order (default
    all, in :data:`CHANNELS` order).
    """

    m_per_px: float = 0.5
    height: int = 128
    width: int = 128
    behind_m: float = 16.0
    channels: tuple[str, ...] = CHANNELS

    def __post_init__(self) -> None:
        if not (self.m_per_px > 0 and math.isfinite(self.m_per_px)):
            raise ValueError(f"BevSpec.m_per_px must be a positive number, got {self.m_per_px}")
        if self.height < 2 or self.width < 2:
            raise ValueError(f"BevSpec size must be at least 2x2 px, got {self.height}x{self.width}")
        bad = [c for c in self.channels if c not in CHANNELS]
        if bad or not self.channels or len(set(self.channels)) != len(self.channels):
            raise ValueError(f"BevSpec.channels must be distinct names among {', '.join(CHANNELS)}, "
                             f"got {self.channels!r}")
        if not 0.0 <= self.behind_m <= self.height * self.m_per_px:
            raise ValueError(
                f"BevSpec.behind_m={self.behind_m} must lie in [0, height * m_per_px = "
                f"{self.height * self.m_per_px}]"
            )

    @property
    def ego_row(self) -> float:
        """Row of the ego centre (px): ``height - behind_m / m_per_px``."""
        return self.height - self.behind_m / self.m_per_px

    @property
    def ego_col(self) -> float:
        """Column of the ego centre (px): ``width / 2``."""
        return self.width / 2.0

    @property
    def ahead_m(self) -> float:
        """View ahead of the ego centre (m)."""
        return self.height * self.m_per_px - self.behind_m

    @property
    def view_radius_m(self) -> float:
        """Distance (m) from the ego centre to the farthest corner of the view."""
        half_w = self.width * self.m_per_px / 2.0
        return math.hypot(max(self.ahead_m, self.behind_m), half_w)


def _fx(v: np.ndarray) -> np.ndarray:
    """Float pixel coordinates -> cv2 fixed-point int32 (``shift=_SHIFT``)."""
    return np.round(np.asarray(v, dtype=np.float64) * _ONE).astype(np.int32)


def _offset_polyline(shape: np.ndarray, offset: float) -> np.ndarray:
    """Polyline (N, 2) shifted ``offset`` m to its left (negative: right), mitred at vertices."""
    d = np.diff(shape, axis=0)
    n = np.hypot(d[:, 0], d[:, 1])
    keep = n > 1e-9
    if not keep.any():
        return shape.copy()
    u = d / np.where(keep, n, 1.0)[:, None]
    u[~keep] = u[keep][0]
    left = np.stack([-u[:, 1], u[:, 0]], axis=1)          # (N-1, 2) segment left normals
    vn = np.empty_like(shape)
    vn[0], vn[-1] = left[0], left[-1]
    if len(shape) > 2:
        m = left[:-1] + left[1:]
        mn = np.hypot(m[:, 0], m[:, 1])
        m = np.where(mn[:, None] > 1e-9, m / np.maximum(mn, 1e-9)[:, None], left[1:])
        cos_half = np.clip((m * left[1:]).sum(axis=1), 0.5, 1.0)  # mitre limit: 2x
        vn[1:-1] = m / cos_half[:, None]
    return shape + vn * offset


class BevRenderer:
    """BEV rasteriser for one network; see the module docstring for the frame convention.

    Holds the pre-rendered static canvas (a few MB for the bundled towns) and the traffic-light
    stop-line segments; :meth:`render` is pure given its arguments (byte-identical output for the
    same inputs).
    """

    def __init__(self, net: RoadNet, spec: BevSpec = BevSpec()) -> None:  # noqa: B008
        self.net = net
        self.spec = spec
        sn = net.sumolib_net
        self._widths = {lid: float(sn.getLane(lid).getWidth()) for lid in sorted(net.lane_shape)}
        pts = np.concatenate([net.lane_shape[lid] for lid in sorted(net.lane_shape)])
        pad = _MARGIN_M + max(self._widths.values(), default=0.0)
        #: world x of canvas column 0 and world y of canvas row 0 (pixel centres), m
        self.x0 = float(pts[:, 0].min() - pad)
        self.y1 = float(pts[:, 1].max() + pad)
        mpp = spec.m_per_px
        w = int(math.ceil((pts[:, 0].max() + pad - self.x0) / mpp)) + 1
        h = int(math.ceil((self.y1 - (pts[:, 1].min() - pad)) / mpp)) + 1
        #: static canvas (H_net, W_net, 3): drivable, markings, stop-sign lines; 0 or 255
        self.canvas = np.zeros((h, w, 3), dtype=np.uint8)
        #: stop-line thickness (px)
        self._stop_px = max(1, int(round(STOP_LINE_M / mpp)))
        self._draw_static()
        self._build_tls()
        #: output channel order as indices into CHANNELS (None: all, in order)
        self._select = None if tuple(spec.channels) == CHANNELS else \
            np.array([CHANNELS.index(c) for c in spec.channels])
        self._tl_cache: dict[tuple[int, str], np.ndarray] = {}
        self._tl_draw_cache: dict[tuple, tuple[np.ndarray, tuple]] = {}
        self._ego_cache: dict[tuple[float, float], np.ndarray] = {}
        #: the ego pose (x, y, yaw) of the last render and its static layers (3, H, W)
        self._static_pose: tuple[float, float, float] | None = None
        self._static: np.ndarray | None = None
        self._view_radius = spec.view_radius_m
        #: per light: centre x, y and the squared visibility radius (view reach + its extent)
        lims = ((self._view_radius + self._tl_radius) ** 2).tolist()  # array square: x * x
        self._tl_near = [(x, y, lim) for (x, y), lim in zip(self._tl_centre.tolist(), lims)]

    # ------------------------------------------------------------------ static layers
    def _world_to_canvas(self, p: np.ndarray) -> np.ndarray:
        """World (..., 2) m -> canvas (col, row) float px."""
        p = np.asarray(p, dtype=np.float64)
        return np.stack(
            [(p[..., 0] - self.x0) / self.spec.m_per_px, (self.y1 - p[..., 1]) / self.spec.m_per_px],
            axis=-1,
        )

    def drivable_at(self, points: np.ndarray) -> np.ndarray:
        """Whether each world point (N, 2) m lies on the drivable area (car lanes, junctions);
        points outside the canvas are not drivable. Returns (N,) bool."""
        cr = np.rint(self._world_to_canvas(np.asarray(points, dtype=float).reshape(-1, 2))).astype(int)
        h, w = self.canvas.shape[:2]
        inside = (cr[:, 0] >= 0) & (cr[:, 0] < w) & (cr[:, 1] >= 0) & (cr[:, 1] < h)
        out = np.zeros(len(cr), dtype=bool)
        out[inside] = self.canvas[cr[inside, 1], cr[inside, 0], 0] > 0
        return out

    def _stop_line(self, lane_id: str) -> tuple[np.ndarray, np.ndarray]:
        """Stop line of a lane: (left end, right end) in world m, perpendicular to the lane's last
        segment, set back half a line thickness from the lane end; drawn with the stop-line
        thickness (round caps) it spans the lane width."""
        shape = self.net.lane_shape[lane_id]
        end = shape[-1]
        d = end - shape[-2] if len(shape) > 1 else np.array([1.0, 0.0])
        d = d / max(float(np.hypot(*d)), 1e-9)
        left = np.array([-d[1], d[0]])
        thick = self._stop_px * self.spec.m_per_px
        c = end - d * (thick / 2.0)
        # cv2's thick lines have round caps of half the thickness: inset the ends by as much
        half = max(self._widths[lane_id] / 2.0 - thick / 2.0, 0.0)
        return c + left * half, c - left * half

    def _draw_static(self) -> None:
        net = self.net
        mpp = self.spec.m_per_px
        drivable = np.zeros(self.canvas.shape[:2], dtype=np.uint8)
        markings = np.zeros_like(drivable)
        stop = np.zeros_like(drivable)
        for lid in sorted(net.lane_shape):
            shape = net.lane_shape[lid]
            half = self._widths[lid] / 2.0
            if len(shape) >= 2:
                lft = self._world_to_canvas(_offset_polyline(shape, half))
                rgt = self._world_to_canvas(_offset_polyline(shape, -half))
                # one convex quad per segment (mitred corners join them), discs at the joints
                for k in range(len(shape) - 1):
                    quad = np.stack([lft[k], lft[k + 1], rgt[k + 1], rgt[k]])
                    cv2.fillConvexPoly(drivable, _fx(quad), 255, cv2.LINE_8, _SHIFT)
                c = _fx(self._world_to_canvas(shape))
                r = int(round(half / mpp * _ONE))
                for k in range(1, len(shape) - 1):
                    cv2.circle(drivable, (int(c[k, 0]), int(c[k, 1])), r, 255, -1, cv2.LINE_8, _SHIFT)
                if not lid.startswith(":"):
                    # lane boundaries: between lanes of one edge and the road edges
                    cv2.polylines(markings, [_fx(lft), _fx(rgt)], False, 255, 1, cv2.LINE_4, _SHIFT)
        for a, b in self._stop_sign_lines():
            pa, pb = _fx(self._world_to_canvas(np.stack([a, b])))
            cv2.line(stop, tuple(map(int, pa)), tuple(map(int, pb)), 255, self._stop_px, cv2.LINE_8, _SHIFT)
        self.canvas[..., 0] = drivable
        self.canvas[..., 1] = markings
        self.canvas[..., 2] = stop

    def _stop_sign_lines(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Stop lines of car lanes that end at a stop-sign junction and must stop there (a
        connection with state 's' at priority_stop or 'w' at allway_stop nodes)."""
        sn = self.net.sumolib_net
        out = []
        for lid in sorted(self.net.lane_shape):
            if lid.startswith(":"):
                continue
            lane = sn.getLane(lid)
            if lane.getEdge().getToNode().getType() not in _STOP_SIGN_NODES:
                continue
            if any(
                c.getState() in _STOP_SIGN_STATES and c.getToLane().allows(EGO_VCLASS)
                for c in lane.getOutgoing()
            ):
                out.append(self._stop_line(lid))
        return out

    def _build_tls(self) -> None:
        """Traffic-light stop lines: per controlled car lane, its stop line split into one
        sub-segment per link, ordered from the lane's left (U-turn, left) to its right (right)."""
        sn = self.net.sumolib_net
        ids, seg_a, seg_b, link, owner = [], [], [], [], []
        for tls in sorted(sn.getTrafficLights(), key=lambda t: t.getID()):
            tid = tls.getID()
            per_lane: dict[str, dict[int, str]] = {}
            for idx, entries in sorted(tls.getLinks().items()):
                for entry in entries:
                    in_lane = entry[0]
                    lid = in_lane.getID()
                    if lid.startswith(":") or lid not in self.net.lane_shape:
                        continue
                    direction = "s"
                    for c in in_lane.getOutgoing():
                        if c.getTLSID() == tid and c.getTLLinkIndex() == idx:
                            direction = c.getDirection()
                            break
                    per_lane.setdefault(lid, {})[int(idx)] = direction
            if not per_lane:
                continue
            k_tls = len(ids)
            ids.append(tid)
            for lid in sorted(per_lane):
                links = sorted(per_lane[lid].items(), key=lambda kv: (_DIR_ORDER.get(kv[1], 3), kv[0]))
                a, b = self._stop_line(lid)
                n = len(links)
                for j, (idx, _d) in enumerate(links):
                    seg_a.append(a + (b - a) * (j / n))
                    seg_b.append(a + (b - a) * ((j + 1) / n))
                    link.append(idx)
                    owner.append(k_tls)
        #: traffic-light ids with stop lines, sorted
        self.tls_ids: tuple[str, ...] = tuple(ids)
        self._tl_a = np.asarray(seg_a, dtype=np.float64).reshape(-1, 2)
        self._tl_b = np.asarray(seg_b, dtype=np.float64).reshape(-1, 2)
        self._tl_seg = np.stack([self._tl_a, self._tl_b], axis=1)  # (K, 2, 2)
        self._tl_link = np.asarray(link, dtype=np.int64)
        owner_arr = np.asarray(owner, dtype=np.int64)
        self._tl_rows = [np.nonzero(owner_arr == k)[0] for k in range(len(ids))]
        mids = (self._tl_a + self._tl_b) / 2.0
        cen, rad = [], []
        for rows in self._tl_rows:
            c = mids[rows].mean(axis=0)
            cen.append(c)
            ends = np.concatenate([self._tl_a[rows], self._tl_b[rows]])
            rad.append(float(np.hypot(*(ends - c).T).max()))
        self._tl_centre = np.asarray(cen, dtype=np.float64).reshape(-1, 2)
        self._tl_radius = np.asarray(rad, dtype=np.float64)

    @property
    def tl_segments(self) -> list[tuple[str, int, np.ndarray]]:
        """Traffic-light stop lines: (tls id, link index, (2, 2) endpoints in world m)."""
        out = []
        for k, rows in enumerate(self._tl_rows):
            for r in rows:
                out.append((self.tls_ids[k], int(self._tl_link[r]), np.stack([self._tl_a[r], self._tl_b[r]])))
        return out

    # ------------------------------------------------------------------ per step
    def _ego_layer(self, length: float, width: float) -> np.ndarray:
        """The ego channel for an ego of ``length`` x ``width`` m (cached per size)."""
        key = (length, width)
        got = self._ego_cache.get(key)
        if got is None:
            sp = self.spec
            r0, c0 = sp.ego_row, sp.ego_col
            hl, hw = length / 2.0 / sp.m_per_px, width / 2.0 / sp.m_per_px
            poly = _fx([[c0 - hw, r0 - hl], [c0 + hw, r0 - hl], [c0 + hw, r0 + hl], [c0 - hw, r0 + hl]])
            got = np.zeros((sp.height, sp.width), dtype=np.uint8)
            cv2.fillConvexPoly(got, poly, 255, cv2.LINE_8, _SHIFT)
            got.setflags(write=False)
            if len(self._ego_cache) > 16:
                self._ego_cache.clear()
            self._ego_cache[key] = got
        return got

    def _tl_draw(self, key: tuple[tuple[int, str], ...]) -> tuple[np.ndarray, tuple]:
        """Stop-line segments (n, 2, 2) world m of the visible lights ``key`` ((tls index,
        state), ...) and the masks of those drawn 'stop' and 'go' (None: none), cached."""
        got = self._tl_draw_cache.get(key)
        if got is None:
            seg = self._tl_seg[np.concatenate([self._tl_rows[k] for k, _ in key])]
            cls_all = np.concatenate([self._tl_classes(k, state) for k, state in key])
            masks = tuple(m if m.any() else None for m in (cls_all == 1, cls_all == 2))
            if len(self._tl_draw_cache) > 4096:
                self._tl_draw_cache.clear()
            got = self._tl_draw_cache[key] = (seg, masks)
        return got

    def _tl_classes(self, k: int, state: str) -> np.ndarray:
        """Per stop-line segment of tls ``k``: 0 nothing, 1 stop, 2 go (cached per state)."""
        key = (k, state)
        got = self._tl_cache.get(key)
        if got is None:
            codes = _TL_CLASS[np.frombuffer(state.encode("ascii", "replace"), dtype=np.uint8)]
            links = self._tl_link[self._tl_rows[k]]
            got = np.zeros(len(links), dtype=np.uint8)
            ok = links < len(codes)
            got[ok] = codes[links[ok]]
            if len(self._tl_cache) > 4096:
                self._tl_cache.clear()
            self._tl_cache[key] = got
        return got

    def render(
        self,
        ego: tuple[float, float, float],
        ego_size: tuple[float, float],
        vehicles: np.ndarray,
        pedestrians: np.ndarray,
        tl_states: dict[str, str],
    ) -> np.ndarray:
        """Rasterise one step.

        ego: (x, y, yaw) of the ego's CENTRE, SUMO coordinates (m), yaw in rad counter-clockwise
        from +x. ego_size: (length, width) m. vehicles: (N, 5) other vehicles' centre x, y (m),
        yaw (rad), length, width (m); pedestrians: (M, 2) centres (m), drawn as
        ``PEDESTRIAN_M`` squares (at least 2 px). tl_states: tls id -> SUMO state string, one
        character per link index: r/R/y/Y/s -> 'stop', g/G -> 'go', others (o/O/u/...) nothing;
        a tls missing from the dict draws nothing. Empty arrays (or ``None``) draw nothing.

        Returns a new ``(len(spec.channels), height, width)`` uint8 array of 0/255 (see
        :data:`CHANNELS`).
        """
        sp = self.spec
        mpp = sp.m_per_px
        ex, ey, yaw = float(ego[0]), float(ego[1]), float(ego[2])
        c, s = math.cos(yaw), math.sin(yaw)
        r0, c0 = sp.ego_row, sp.ego_col
        out = np.zeros((len(CHANNELS), sp.height, sp.width), dtype=np.uint8)
        if self._static_pose == (ex, ey, yaw):
            # an ego standing still: the static layers of the render before, unchanged
            out[_STATIC] = self._static
        else:
            # static layers: output pixel (col, row) -> canvas (col, row), one warp for all three
            tx = (ex - self.x0) / mpp + r0 * c - c0 * s
            ty = (self.y1 - ey) / mpp - r0 * s - c0 * c
            warped = cv2.warpAffine(
                self.canvas, np.array([[s, -c, tx], [c, s, ty]]), (sp.width, sp.height),
                flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0),
            )
            cv2.split(warped, [out[_DRIVABLE], out[_MARKINGS], out[_STOP]])
            self._static_pose, self._static = (ex, ey, yaw), out[_STATIC].copy()
        # world (x, y) m -> ego-frame fixed-point (col, row): p @ lin + off
        a, b = s / mpp * _ONE, c / mpp * _ONE
        lin = np.array([[a, -b], [-b, -a]])
        off = np.array([c0 * _ONE - a * ex + b * ey, r0 * _ONE + b * ex + a * ey])
        reach = self._view_radius

        # vehicles: rotated rectangles
        if vehicles is not None and len(vehicles):
            veh = np.asarray(vehicles, dtype=np.float64).reshape(-1, 5)
            d2 = (veh[:, 0] - ex) ** 2 + (veh[:, 1] - ey) ** 2
            # Python's math (libm's cos and sin, CPython's own hypot) one value at a time, not
            # numpy's SIMD loops, which may round differently on another CPU
            half = np.array([math.hypot(vl, vw) for vl, vw in veh[:, 3:5].tolist()]) * 0.5
            veh = veh[d2 <= (reach + half) ** 2]
            if len(veh):
                yaws = veh[:, 2].tolist()
                cy, sy = np.array([math.cos(v) for v in yaws]), np.array([math.sin(v) for v in yaws])
                u = np.stack([cy, sy], axis=1) @ lin * (veh[:, 3:4] / 2.0)   # half length, px
                v = np.stack([-sy, cy], axis=1) @ lin * (veh[:, 4:5] / 2.0)  # half width, px
                ctr = veh[:, :2] @ lin + off
                polys = np.rint(
                    ctr[:, None, :] + _CORNER_L[None, :, None] * u[:, None, :]
                    + _CORNER_W[None, :, None] * v[:, None, :]
                ).astype(np.int32)
                layer = out[_VEHICLES]
                for poly in polys:
                    cv2.fillConvexPoly(layer, poly, 255, cv2.LINE_8, _SHIFT)
        # pedestrians: squares in the ego frame (a handful per frame: plain Python around the
        # one transform, the same arithmetic as on arrays)
        if pedestrians is not None and len(pedestrians):
            lim = (reach + PEDESTRIAN_M) ** 2
            near = []
            for px, py in np.asarray(pedestrians, dtype=np.float64).reshape(-1, 2).tolist():
                dx, dy = px - ex, py - ey
                if dx * dx + dy * dy <= lim:
                    near.append((px, py))
            if near:
                ctr = ((np.array(near) @ lin + off) / _ONE).tolist()
                h = max(PEDESTRIAN_M / 2.0 / mpp, 1.0)
                layer = out[_PEDESTRIANS]
                floor, w_px, h_px = math.floor, sp.width, sp.height
                for cx, cy in ctr:
                    x_lo, y_lo = max(floor(cx - h + 0.5), 0), max(floor(cy - h + 0.5), 0)
                    x_hi, y_hi = min(floor(cx + h + 0.5), w_px), min(floor(cy + h + 0.5), h_px)
                    if x_lo < x_hi and y_lo < y_hi:
                        layer[y_lo:y_hi, x_lo:x_hi] = 255
        # ego: axis-aligned in its own frame, the same layer every frame
        out[_EGO] = self._ego_layer(float(ego_size[0]), float(ego_size[1]))
        # traffic-light stop lines of the lights near enough to be seen
        if tl_states and self._tl_near:
            key = []
            for k, (cx, cy, lim) in enumerate(self._tl_near):
                dx, dy = cx - ex, cy - ey
                if dx * dx + dy * dy <= lim:
                    state = tl_states.get(self.tls_ids[k])
                    if state:
                        key.append((k, state))
            if key:
                seg, masks = self._tl_draw(tuple(key))
                pts = np.rint(seg @ lin + off).astype(np.int32)
                for mask, ch in zip(masks, (_STOP, _GO)):
                    if mask is not None:
                        cv2.polylines(out[ch], pts[mask], False, 255, self._stop_px, cv2.LINE_8, _SHIFT)
        return out if self._select is None else out[self._select]
