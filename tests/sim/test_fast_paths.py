"""The closed loop's per-step fast paths give exactly (float for float, pixel for pixel) what
their straightforward reference forms give: episode logs must not change when the loop gets
faster."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from icrsumo.core.resources import bundled_towns
from icrsumo.render import BevRenderer, BevSpec
from icrsumo.sim.control import WaypointController, WaypointPath, desired_speed, pursuit_point
from icrsumo.sim.drivable import drivable_area
from icrsumo.sim.sensors import LaneHeading, footprint_corners, off_corners
from icrsumo.world.dynamics import Control, EgoState, VehicleParams
from icrsumo.world.networks import load_net


# ----------------------------------------------------------------------------- references
class _RefController:
    """The controller as first written: numpy on every call."""

    def __init__(self, params: VehicleParams) -> None:
        self.params, self.kp, self.ki, self._integral = params, 0.6, 0.1, 0.0

    def control(self, waypoints, speed, dt, target_speed=None) -> Control:
        v_des = desired_speed(waypoints) if target_speed is None else target_speed
        lookahead = float(np.clip(2.5 + 0.6 * speed, 3.0, 15.0))
        px, py = pursuit_point(waypoints, lookahead)
        ld2 = max(px * px + py * py, 1e-6)
        curvature = 2.0 * py / ld2
        steer_angle = math.atan(self.params.wheelbase * curvature)
        steer = float(np.clip(steer_angle / self.params.max_steer, -1.0, 1.0))
        if v_des < 0.3:
            self._integral = 0.0
            return Control(steer=steer, throttle=0.0, brake=1.0 if speed > 0.05 else 0.6)
        err = v_des - speed
        self._integral = float(np.clip(self._integral + err * dt, -5.0, 5.0))
        u = self.kp * err + self.ki * self._integral
        if u >= 0:
            return Control(steer=steer, throttle=float(min(u, 1.0)), brake=0.0)
        return Control(steer=steer, throttle=0.0, brake=float(min(-u * 0.5, 1.0)))


def _random_waypoints(rng: np.random.Generator) -> np.ndarray:
    n = int(rng.integers(1, 9))
    kind = rng.integers(4)
    if kind == 0:  # a forward trajectory
        wps = np.cumsum(rng.uniform(0.0, 6.0, (n, 2)) * [1.0, 0.3], axis=0)
    elif kind == 1:  # anywhere
        wps = rng.uniform(-20.0, 20.0, (n, 2))
    elif kind == 2:  # repeated points, zero-length segments
        wps = np.repeat(rng.uniform(-3.0, 3.0, (1, 2)), n, axis=0)
    else:  # standing still
        wps = np.zeros((n, 2))
    return wps.round(int(rng.integers(1, 12)))


# ----------------------------------------------------------------------------- tests
def test_controller_is_the_reference_float_for_float():
    rng = np.random.default_rng(7)
    params = VehicleParams()
    for _ in range(300):
        fast, ref = WaypointController(params), _RefController(params)
        wps = _random_waypoints(rng)
        path = WaypointPath(wps)
        assert path.speed == desired_speed(wps)
        for lookahead in (0.0, 1e-7, 3.0, 7.5, 15.0, 40.0, float(path.total), float(path.cum[-1]) + 1e-9):
            assert path.point(lookahead) == tuple(pursuit_point(wps, lookahead))
        ts = [None, 0.0, 0.29, 4.0, float(rng.uniform(0, 20)), np.float32(rng.uniform(0, 20))]
        target = ts[int(rng.integers(len(ts)))]
        for _ in range(6):  # an action held over steps: the integral carries over
            speed = float(rng.choice([0.0, 0.04, 0.2, rng.uniform(0, 30)]))
            a = fast.control(path, speed, 0.05, target)
            b = ref.control(wps, speed, 0.05, target)
            assert (a.steer, a.throttle, a.brake) == (b.steer, b.throttle, b.brake)
            assert fast._integral == ref._integral
        c = WaypointController(params).control(wps, 3.0, 0.05)  # plain arrays still work
        d = _RefController(params).control(wps, 3.0, 0.05)
        assert c == d


@pytest.fixture(scope="module", params=["icr_grid", "icr_roundabout", "icr_rural"])
def town(request):
    net = load_net(bundled_towns()[request.param])
    return net, BevRenderer(net, BevSpec())


def test_lane_heading_is_lane_pose(town):
    net, _ = town
    heading = LaneHeading(net)
    for lane in sorted(net.lane_shape):
        length = net.lane_length[lane]
        for pos in (-1.0, 0.0, 0.3 * length, 0.5 * length, 0.77 * length, length - 1e-9, length,
                    length + 2.0):
            assert heading(lane, pos) == net.lane_pose(lane, pos)[2], (lane, pos)


def test_footprint_and_drivable_lookup_are_the_array_forms(town):
    net, _ = town
    area = drivable_area(net)
    rng = np.random.default_rng(11)
    pts = np.concatenate(list(net.lane_shape.values()))
    size = (4.9, 2.1)
    for _ in range(3000):
        x, y = pts[int(rng.integers(len(pts)))] + rng.normal(0.0, 2.5, 2)
        st = EgoState(float(x), float(y), float(rng.uniform(-math.pi, math.pi)))
        corners = footprint_corners(st, size)
        seen: list = []
        assert off_corners(st, size, lambda p, seen=seen: seen.extend(p) or 0) == 0
        assert np.array_equal(np.array(seen), corners)  # the same corners, float for float
        assert off_corners(st, size, area.count_off) == int((~area.contains_xy(corners)).sum())


def test_render_static_and_ego_layers_are_the_canvas_warp(town):
    """The static layers are the warped canvas; the cached ego layer equals drawing it."""
    _, r = town
    sp = r.spec
    rng = np.random.default_rng(5)
    h, w = r.canvas.shape[:2]
    for i in range(300):
        ex = r.x0 + rng.uniform(-40.0, w * sp.m_per_px + 40.0)
        ey = r.y1 - rng.uniform(-40.0, h * sp.m_per_px + 40.0)
        yaw = float(rng.uniform(-4.0, 4.0)) if i % 5 else float(rng.choice([0.0, math.pi / 2, -math.pi]))
        size = (4.9, 2.1) if i % 3 else (float(rng.uniform(2.0, 12.0)), float(rng.uniform(1.0, 3.0)))
        got = r.render((ex, ey, yaw), size, None, None, {})
        c, s = math.cos(yaw), math.sin(yaw)
        r0, c0, mpp = sp.ego_row, sp.ego_col, sp.m_per_px
        m = np.array([[s, -c, (ex - r.x0) / mpp + r0 * c - c0 * s],
                      [c, s, (r.y1 - ey) / mpp - r0 * s - c0 * c]])
        warped = cv2.warpAffine(r.canvas, m, (sp.width, sp.height),
                                flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                                borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0))
        for ch, k in ((0, 0), (1, 1), (5, 2)):
            assert np.array_equal(got[ch], warped[..., k])
        ego = np.zeros((sp.height, sp.width), np.uint8)
        hl, hw = size[0] / 2.0 / mpp, size[1] / 2.0 / mpp
        poly = np.round(np.array([[c0 - hw, r0 - hl], [c0 + hw, r0 - hl], [c0 + hw, r0 + hl],
                                  [c0 - hw, r0 + hl]]) * 16).astype(np.int32)
        cv2.fillConvexPoly(ego, poly, 255, cv2.LINE_8, 4)
        assert np.array_equal(got[4], ego)
        assert not got[[2, 3, 6]].any()


def _ref_dynamic(r: BevRenderer, ego, vehicles, pedestrians, tl_states) -> np.ndarray:
    """Vehicles, pedestrians and traffic-light stop lines drawn as first written (arrays only):
    planes vehicles, pedestrians, stop (traffic lights only), go."""
    from icrsumo.render.bev import _CORNER_L, _CORNER_W, _ONE, _SHIFT, PEDESTRIAN_M

    sp, mpp = r.spec, r.spec.m_per_px
    ex, ey, yaw = ego
    c, s = math.cos(yaw), math.sin(yaw)
    r0, c0 = sp.ego_row, sp.ego_col
    out = np.zeros((4, sp.height, sp.width), np.uint8)
    a, b = s / mpp * _ONE, c / mpp * _ONE
    lin = np.array([[a, -b], [-b, -a]])
    off = np.array([c0 * _ONE - a * ex + b * ey, r0 * _ONE + b * ex + a * ey])
    reach = r._view_radius
    veh = np.asarray(vehicles, dtype=np.float64).reshape(-1, 5)
    d2 = (veh[:, 0] - ex) ** 2 + (veh[:, 1] - ey) ** 2
    veh = veh[d2 <= (reach + 0.5 * np.hypot(veh[:, 3], veh[:, 4])) ** 2]
    if len(veh):
        cy, sy = np.cos(veh[:, 2]), np.sin(veh[:, 2])
        u = np.stack([cy, sy], axis=1) @ lin * (veh[:, 3:4] / 2.0)
        v = np.stack([-sy, cy], axis=1) @ lin * (veh[:, 4:5] / 2.0)
        ctr = veh[:, :2] @ lin + off
        polys = np.rint(ctr[:, None, :] + _CORNER_L[None, :, None] * u[:, None, :]
                        + _CORNER_W[None, :, None] * v[:, None, :]).astype(np.int32)
        for poly in polys:
            cv2.fillConvexPoly(out[0], poly, 255, cv2.LINE_8, _SHIFT)
    ped = np.asarray(pedestrians, dtype=np.float64).reshape(-1, 2)
    d2 = (ped[:, 0] - ex) ** 2 + (ped[:, 1] - ey) ** 2
    ped = ped[d2 <= (reach + PEDESTRIAN_M) ** 2]
    if len(ped):
        ctr = (ped @ lin + off) / _ONE
        h = max(PEDESTRIAN_M / 2.0 / mpp, 1.0)
        lo = np.maximum(np.floor(ctr - h + 0.5), 0).astype(np.int64)
        hi = np.minimum(np.floor(ctr + h + 0.5), [sp.width, sp.height]).astype(np.int64)
        for x_lo, y_lo, x_hi, y_hi in np.concatenate([lo, hi], axis=1).tolist():
            if x_lo < x_hi and y_lo < y_hi:
                out[1, y_lo:y_hi, x_lo:x_hi] = 255
    if tl_states and len(r._tl_centre):
        d2 = (r._tl_centre[:, 0] - ex) ** 2 + (r._tl_centre[:, 1] - ey) ** 2
        rows, cls = [], []
        for k in np.nonzero(d2 <= (reach + r._tl_radius) ** 2)[0].tolist():
            state = tl_states.get(r.tls_ids[k])
            if state:
                rows.append(r._tl_rows[k])
                cls.append(r._tl_classes(k, state))
        if rows:
            pts = np.rint(r._tl_seg[np.concatenate(rows)] @ lin + off).astype(np.int32)
            cls_all = np.concatenate(cls)
            for which, ch in ((1, 2), (2, 3)):
                sel = pts[cls_all == which]
                if len(sel):
                    cv2.polylines(out[ch], sel, False, 255, r._stop_px, cv2.LINE_8, _SHIFT)
    return out


def test_render_dynamic_layers_are_the_array_forms(town):
    net, r = town
    rng = np.random.default_rng(9)
    pts = np.concatenate(list(net.lane_shape.values()))
    states = list("rRyYgGsuoO")
    for i in range(250):
        ex, ey = (pts[int(rng.integers(len(pts)))] + rng.normal(0.0, 5.0, 2)).tolist()
        yaw = float(rng.uniform(-4.0, 4.0))
        nv, npd = int(rng.integers(0, 30)), int(rng.integers(0, 20))
        veh = np.column_stack([ex + rng.uniform(-80, 80, nv), ey + rng.uniform(-80, 80, nv),
                               rng.uniform(-4, 4, nv), rng.uniform(2, 15, nv), rng.uniform(1, 3, nv)])
        ped = np.column_stack([ex + rng.uniform(-70, 70, npd), ey + rng.uniform(-70, 70, npd)])
        tls = {t: "".join(rng.choice(states, int(rng.integers(0, 20))))
               for t in r.tls_ids if rng.random() < 0.9}
        got = r.render((ex, ey, yaw), (4.9, 2.1), veh, ped, tls if i % 5 else {})
        ref = _ref_dynamic(r, (ex, ey, yaw), veh, ped, tls if i % 5 else {})
        assert np.array_equal(got[2], ref[0]) and np.array_equal(got[3], ref[1])
        assert np.array_equal(got[6], ref[3])
        static_stop = r.render((ex, ey, yaw), (4.9, 2.1), None, None, {})[5]
        assert np.array_equal(got[5], np.maximum(ref[2], static_stop))
