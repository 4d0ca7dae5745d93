"""Generate the six icrsumo towns as SUMO networks (networks/<name>.net.xml).

Usage: python tools/make_networks.py [--out networks] [--report]

Every town is written as plain node/edge(/connection) XML into a temporary
folder and converted with netconvert (found via ``sumo.SUMO_HOME/bin``) using
the fixed options in COMMON_OPTIONS (+ PED_OPTIONS for towns with sidewalks).
The leading ``<!-- generated on ... -->`` header comment (date, temp paths) is
stripped, so the output is byte-identical on every run.  All towns: right-hand
traffic, coordinates in metres, netOffset 0,0 and no projection
(--offset.disable-normalization), no U-turns except at dead ends (there are
none), lane width 3.2 m (highway 3.5 m), strongly connected for passenger cars
(check with --report).  Sidewalk lanes (index 0, 2 m) allow only pedestrians;
car lanes disallow only pedestrians (highway main lanes also bicycle/moped).

Towns (junction counts exclude internal junctions):

* icr_grid -- 6x5 urban grid, blocks 120-140 m, bbox 60,60-720,560; 49 two-way
  roads (98 edges), 1 lane each way, 50 km/h; the 12 inner 4-way
  intersections are traffic_light, the 18 border nodes priority; sidewalks on
  every edge, 94 crossings (4 per signalised crossroads, 3 per border T,
  1 per corner).
* icr_tjunctions -- brick pattern of 5 east-west streets with staggered
  north-south links (150 m x 130 m), bbox 60,60-960,580; 86 edges, 1 lane
  each way, 50 km/h; all non-corner nodes are T-junctions: 9 priority_stop,
  4 allway_stop, 4 traffic_light, 9 priority (+4 corners); sidewalks,
  82 crossings.
* icr_arterial -- 5x4 grid (200 m x 180 m), bbox 60,60-860,600; arterial
  y=240 with 3 lanes each way (60 km/h), arterial y=420 and avenue x=460 with
  2 lanes each way, other streets 1 lane (50 km/h); 12 traffic_light, 8
  priority.  Explicit lane connections everywhere: right turns only from the
  rightmost lane, left turns only from the leftmost lane (3-lane approaches:
  dedicated left lane, lanes 0-1 straight), so lane changes are needed;
  sidewalks, 58 crossings.
* icr_roundabout -- two one-lane roundabouts, R1 (r=28 m, centre 400,350) and
  R2 (r=18 m, centre 850,350), both with 4 arms and written as <roundabout>;
  ring 30 km/h, other roads 50 km/h, 1 lane each way; a street frame around
  them (priority junctions, one traffic_light at E between the roundabouts),
  bbox 100,100-1000,600; 52 edges; sidewalks (also around the rings),
  40 crossings.
* icr_highway -- 1.8 km highway (bbox 50,80-1850,520), separate carriageways
  with 3 lanes (120 km/h, 80 km/h on the end links) each way; per direction
  two off-ramps (150 m deceleration lane, exit-only lane 0) and two on-ramps
  (acceleration lane of 140-180 m ending in a zipper merge), ramps 60 km/h to
  signalised ramp terminals on local 2-row street grids (1 lane, 50 km/h)
  south and north of the highway; both highway ends are signalised junctions
  in the local grid; two local streets pass under the highway.  134 edges,
  6 traffic_light, 4 zipper, 48 priority; no sidewalks.
* icr_rural -- distorted 3x3 rural network (bbox ~83,50-997,945) of 12 two-way
  roads, each 360-450 m with bends or S-curves (shape points), 1 lane each
  way, 70-80 km/h; 3 priority_stop T-junctions, 2 allway_stop junctions
  (incl. the central 4-way), 4 priority corners; no sidewalks.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections import Counter, deque

KMH = 1.0 / 3.6
SIDEWALK_WIDTH = 2.0
LANE_WIDTH = 3.2

# netconvert options shared by every town (see module docstring)
COMMON_OPTIONS = [
    "--offset.disable-normalization", "true",
    "--no-turnarounds.except-deadend", "true",
    "--default.lanewidth", f"{LANE_WIDTH:.1f}",
    "--default.junctions.radius", "4",
    "--junctions.corner-detail", "5",
    "--junctions.join", "false",
    "--roundabouts.guess", "true",
    "--tls.default-type", "static",
    "--tls.guess", "false",
    "--ramps.guess", "false",
    "--geometry.remove", "false",
    "--precision", "2",
    "--output.street-names", "false",
    "--output.original-names", "false",
    "--xml-validation", "never",
]
PED_OPTIONS = [
    "--crossings.guess", "true",
    "--walkingareas", "true",
]


def speed(kmh: float) -> float:
    return round(kmh * KMH, 2)


class Net:
    """A plain-XML network description (nodes, edges, connections)."""

    def __init__(self, name: str, sidewalks: bool):
        self.name = name
        self.sidewalks = sidewalks
        self.nodes: dict[str, dict] = {}
        self.edges: dict[str, dict] = {}
        self.conns: list[dict] = []
        self.roundabouts: list[tuple[list[str], list[str]]] = []

    # -- construction helpers -------------------------------------------
    def node(self, nid: str, x: float, y: float, ntype: str = "priority") -> str:
        assert nid not in self.nodes, nid
        self.nodes[nid] = {"id": nid, "x": float(x), "y": float(y), "type": ntype}
        return nid

    def pos(self, nid: str) -> tuple[float, float]:
        n = self.nodes[nid]
        return n["x"], n["y"]

    def edge(self, frm: str, to: str, lanes: int, spd: float, prio: int,
             shape: list | None = None, eid: str | None = None,
             sidewalk: bool | None = None, width: float | None = None,
             disallow: str | None = None) -> str:
        eid = eid or f"E_{frm}_{to}"
        assert eid not in self.edges, eid
        sw = self.sidewalks if sidewalk is None else sidewalk
        self.edges[eid] = {
            "id": eid, "from": frm, "to": to, "lanes": lanes, "speed": spd,
            "priority": prio, "shape": shape, "sidewalk": sw, "width": width,
            "disallow": disallow,
        }
        return eid

    def road(self, a: str, b: str, lanes: int, spd: float, prio: int,
             shape: list | None = None, lanes_back: int | None = None,
             **kw) -> tuple[str, str]:
        """Two-way road a<->b; `shape` (a -> b, incl. end points) is mirrored."""
        back = list(reversed(shape)) if shape else None
        e1 = self.edge(a, b, lanes, spd, prio, shape, **kw)
        e2 = self.edge(b, a, lanes if lanes_back is None else lanes_back,
                       spd, prio, back, **kw)
        return e1, e2

    def conn(self, frm: str, to: str, from_lane: int, to_lane: int) -> None:
        self.conns.append({"from": frm, "to": to, "fromLane": from_lane,
                           "toLane": to_lane})

    def lane_offset(self, eid: str) -> int:
        return 1 if self.edges[eid]["sidewalk"] else 0

    # -- geometry ---------------------------------------------------------
    def _heading(self, eid: str, at_end: bool) -> float:
        e = self.edges[eid]
        pts = e["shape"] or [self.pos(e["from"]), self.pos(e["to"])]
        (x0, y0), (x1, y1) = (pts[-2], pts[-1]) if at_end else (pts[0], pts[1])
        return math.degrees(math.atan2(y1 - y0, x1 - x0))

    def turn(self, e_in: str, e_out: str) -> str:
        a = self._heading(e_out, False) - self._heading(e_in, True)
        a = (a + 180.0) % 360.0 - 180.0
        if a > 35.0:
            return "l"
        if a < -35.0:
            return "r"
        return "s"

    def lane_connections(self, nid: str) -> None:
        """Explicit lane-to-lane connections for all edges entering `nid`:
        right turns only from the rightmost lane, left turns only from the
        leftmost lane, middle lanes straight (no U-turns)."""
        incoming = sorted(e for e, d in self.edges.items() if d["to"] == nid)
        outgoing = sorted(e for e, d in self.edges.items() if d["from"] == nid)
        for ei in incoming:
            src = self.edges[ei]["from"]
            targets = {"r": [], "s": [], "l": []}
            for eo in outgoing:
                if self.edges[eo]["to"] == src:
                    continue  # no U-turn
                targets[self.turn(ei, eo)].append(eo)
            n = self.edges[ei]["lanes"]
            lanes = {"r": [], "s": [], "l": []}
            if targets["s"]:
                if n == 1:
                    lanes = {"r": [0], "s": [0], "l": [0]}
                elif n == 2:
                    lanes = {"r": [0], "s": [0, 1], "l": [1]}
                else:
                    lanes = {"r": [0], "s": list(range(n - 1)), "l": [n - 1]}
            else:
                k = (n + 1) // 2 if targets["r"] and targets["l"] else n
                lanes["r"] = list(range(k)) if targets["r"] else []
                lanes["l"] = list(range(n - k, n)) if not targets["r"] else list(range(k, n))
                if targets["r"] and targets["l"] and n == 1:
                    lanes = {"r": [0], "s": [], "l": [0]}
            oi = self.lane_offset(ei)
            for d in "rsl":
                for eo in targets[d]:
                    m = self.edges[eo]["lanes"]
                    oo = self.lane_offset(eo)
                    src_lanes = lanes[d]
                    for k, li in enumerate(src_lanes):
                        tl = max(0, m - len(src_lanes) + k) if d == "l" else min(k, m - 1)
                        self.conn(ei, eo, li + oi, tl + oo)

    # -- output -------------------------------------------------------------
    def write(self, folder: str) -> list[str]:
        files = []
        p = os.path.join(folder, self.name + ".nod.xml")
        with open(p, "w", encoding="utf-8") as f:
            f.write("<nodes>\n")
            for nid in sorted(self.nodes):
                n = self.nodes[nid]
                f.write(f'    <node id="{nid}" x="{n["x"]:.2f}" y="{n["y"]:.2f}" '
                        f'type="{n["type"]}"/>\n')
            f.write("</nodes>\n")
        files += ["--node-files", p]
        p = os.path.join(folder, self.name + ".edg.xml")
        with open(p, "w", encoding="utf-8") as f:
            f.write("<edges>\n")
            for eid in sorted(self.edges):
                e = self.edges[eid]
                attrs = (f'id="{eid}" from="{e["from"]}" to="{e["to"]}" '
                         f'numLanes="{e["lanes"]}" speed="{e["speed"]:.2f}" '
                         f'priority="{e["priority"]}"')
                if e["width"]:
                    attrs += f' width="{e["width"]:.2f}"'
                if e["disallow"]:
                    attrs += f' disallow="{e["disallow"]}"'
                if e["sidewalk"]:
                    attrs += f' sidewalkWidth="{SIDEWALK_WIDTH:.2f}"'
                if e["shape"]:
                    shape = " ".join(f"{x:.2f},{y:.2f}" for x, y in e["shape"])
                    attrs += f' shape="{shape}"'
                f.write(f"    <edge {attrs}/>\n")
            for nodes, edges in self.roundabouts:
                f.write(f'    <roundabout nodes="{" ".join(nodes)}" '
                        f'edges="{" ".join(edges)}"/>\n')
            f.write("</edges>\n")
        files += ["--edge-files", p]
        if self.conns:
            p = os.path.join(folder, self.name + ".con.xml")
            with open(p, "w", encoding="utf-8") as f:
                f.write("<connections>\n")
                for c in self.conns:
                    f.write(f'    <connection from="{c["from"]}" to="{c["to"]}" '
                            f'fromLane="{c["fromLane"]}" toLane="{c["toLane"]}"/>\n')
                f.write("</connections>\n")
            files += ["--connection-files", p]
        return files


# ---------------------------------------------------------------------------
# geometry helpers
def arc(cx, cy, r, a0, a1, steps):
    """Points on a circle from angle a0 to a1 (degrees), inclusive."""
    return [(cx + r * math.cos(math.radians(a0 + (a1 - a0) * i / steps)),
             cy + r * math.sin(math.radians(a0 + (a1 - a0) * i / steps)))
            for i in range(steps + 1)]


def bezier(ctrl, steps=12):
    """Cubic Bezier polyline through four control points."""
    (ax, ay), (bx, by), (cx, cy), (dx, dy) = ctrl
    pts = []
    for i in range(steps + 1):
        t = i / steps
        u = 1 - t
        w = (u * u * u, 3 * u * u * t, 3 * u * t * t, t * t * t)
        pts.append((w[0] * ax + w[1] * bx + w[2] * cx + w[3] * dx,
                    w[0] * ay + w[1] * by + w[2] * cy + w[3] * dy))
    return pts


def curve(p, q, amp, waves, steps=16):
    """Polyline p->q displaced sideways by amp*sin(pi*waves*t):
    waves=1 gives a single bend, waves=2 an S-curve."""
    (x0, y0), (x1, y1) = p, q
    dx, dy = x1 - x0, y1 - y0
    ln = math.hypot(dx, dy)
    nx, ny = -dy / ln, dx / ln
    pts = []
    for i in range(steps + 1):
        t = i / steps
        o = amp * math.sin(math.pi * waves * t)
        pts.append((x0 + dx * t + nx * o, y0 + dy * t + ny * o))
    return pts


# ---------------------------------------------------------------------------
# towns
def town_grid() -> Net:
    net = Net("icr_grid", sidewalks=True)
    xs = [60, 190, 330, 460, 590, 720]
    ys = [60, 180, 310, 430, 560]
    ni, nj = len(xs), len(ys)
    for i, x in enumerate(xs):
        for j, y in enumerate(ys):
            inner = 0 < i < ni - 1 and 0 < j < nj - 1
            net.node(f"J{i}_{j}", x, y, "traffic_light" if inner else "priority")
    v = speed(50)
    for j in range(nj):
        for i in range(ni - 1):
            border = j in (0, nj - 1)
            net.road(f"J{i}_{j}", f"J{i + 1}_{j}", 1, v, 3 if border else 2)
    for i in range(ni):
        for j in range(nj - 1):
            border = i in (0, ni - 1)
            net.road(f"J{i}_{j}", f"J{i}_{j + 1}", 1, v, 3 if border else 2)
    return net


def town_tjunctions() -> Net:
    net = Net("icr_tjunctions", sidewalks=True)
    ys = [60, 190, 320, 450, 580]
    xs = [60, 210, 360, 510, 660, 810, 960]
    between = {r: ([1, 3, 5] if r % 2 == 0 else [2, 4]) for r in range(len(ys) - 1)}
    rows = {}
    for r in range(len(ys)):
        cols = {0, len(xs) - 1}
        cols |= set(between.get(r, []))
        cols |= set(between.get(r - 1, []))
        rows[r] = sorted(cols)
    # degree-3 nodes get a cycle of controls; corners are plain priority
    cycle = ["priority_stop", "priority", "allway_stop", "priority_stop",
             "traffic_light", "priority"]
    k = 0
    for r in range(len(ys)):
        for c in rows[r]:
            corner = c in (0, len(xs) - 1) and r in (0, len(ys) - 1)
            t = "priority" if corner else cycle[k % len(cycle)]
            if not corner:
                k += 1
            net.node(f"J{c}_{r}", xs[c], ys[r], t)
    v = speed(50)
    for r in range(len(ys)):
        cols = rows[r]
        for a, b in zip(cols, cols[1:], strict=False):
            net.road(f"J{a}_{r}", f"J{b}_{r}", 1, v, 3)
    for r in range(len(ys) - 1):
        for c in [0, len(xs) - 1]:
            net.road(f"J{c}_{r}", f"J{c}_{r + 1}", 1, v, 4)
        for c in between[r]:
            net.road(f"J{c}_{r}", f"J{c}_{r + 1}", 1, v, 2)
    return net


def town_arterial() -> Net:
    net = Net("icr_arterial", sidewalks=True)
    xs = [60, 260, 460, 660, 860]
    ys = [60, 240, 420, 600]
    row_lanes = {0: 1, 1: 3, 2: 2, 3: 1}
    row_speed = {0: speed(50), 1: speed(60), 2: speed(50), 3: speed(50)}
    row_prio = {0: 2, 1: 5, 2: 4, 3: 2}
    col_lanes = {0: 1, 1: 1, 2: 2, 3: 1, 4: 1}
    col_prio = {0: 2, 1: 1, 2: 3, 3: 1, 4: 2}
    for i, x in enumerate(xs):
        for j, y in enumerate(ys):
            corner = i in (0, len(xs) - 1) and j in (0, len(ys) - 1)
            major = row_lanes[j] > 1 or col_lanes[i] > 1
            t = "traffic_light" if major and not corner else "priority"
            net.node(f"J{i}_{j}", x, y, t)
    for j in range(len(ys)):
        for i in range(len(xs) - 1):
            net.road(f"J{i}_{j}", f"J{i + 1}_{j}", row_lanes[j],
                     row_speed[j], row_prio[j])
    for i in range(len(xs)):
        for j in range(len(ys) - 1):
            net.road(f"J{i}_{j}", f"J{i}_{j + 1}", col_lanes[i],
                     speed(50), col_prio[i])
    for nid in sorted(net.nodes):
        net.lane_connections(nid)
    return net


def _roundabout(net: Net, name: str, cx: float, cy: float, r: float,
                spd: float) -> dict[str, str]:
    """Four-node one-lane roundabout, counter-clockwise (right-hand traffic)."""
    ids = {}
    for d, a in (("E", 0), ("N", 90), ("W", 180), ("S", 270)):
        ids[d] = net.node(f"{name}_{d}", cx + r * math.cos(math.radians(a)),
                          cy + r * math.sin(math.radians(a)), "priority")
    order = [("E", 0), ("N", 90), ("W", 180), ("S", 270)]
    ring = []
    for k, (d, a) in enumerate(order):
        d2 = order[(k + 1) % 4][0]
        ring.append(net.edge(ids[d], ids[d2], 1, spd, 10,
                             arc(cx, cy, r, a, a + 90, 12)))
    net.roundabouts.append(([ids[d] for d, _ in order], ring))
    return ids


def town_roundabout() -> Net:
    net = Net("icr_roundabout", sidewalks=True)
    v, vr = speed(50), speed(30)
    r1 = _roundabout(net, "R1", 400, 350, 28, vr)
    r2 = _roundabout(net, "R2", 850, 350, 18, vr)
    # surrounding ordinary street frame
    xs = [100, 400, 700, 850, 1000]
    for x in xs:
        net.node(f"S{x}", x, 100, "priority")
        net.node(f"N{x}", x, 600, "priority")
    net.node("W", 100, 350, "priority")
    net.node("E", 700, 350, "traffic_light")
    net.node("X", 1000, 350, "priority")
    for a, b in zip(xs, xs[1:], strict=False):
        net.road(f"S{a}", f"S{b}", 1, v, 3)
        net.road(f"N{a}", f"N{b}", 1, v, 3)
    net.road("S100", "W", 1, v, 3)
    net.road("W", "N100", 1, v, 3)
    net.road("S1000", "X", 1, v, 3)
    net.road("X", "N1000", 1, v, 3)
    net.road("S700", "E", 1, v, 2)
    net.road("E", "N700", 1, v, 2)
    # roundabout arms
    net.road("W", r1["W"], 1, v, 2)
    net.road("S400", r1["S"], 1, v, 2)
    net.road("N400", r1["N"], 1, v, 2)
    net.road("E", r1["E"], 1, v, 2)
    net.road("E", r2["W"], 1, v, 2)
    net.road("S850", r2["S"], 1, v, 2)
    net.road("N850", r2["N"], 1, v, 2)
    net.road("X", r2["E"], 1, v, 2)
    return net


def town_highway() -> Net:
    """Eastbound half (south side) is built, then rotated by 180 degrees about
    the centre to obtain the westbound half (north side)."""
    net = Net("icr_highway", sidewalks=False)
    x0, x1, cy, hy = 50.0, 1850.0, 300.0, 298.0
    cx = (x0 + x1) / 2
    vh, vend, vramp, vloc = speed(120), speed(80), speed(60), speed(50)
    hw = "pedestrian bicycle moped"
    net.node("HW_W", x0, cy, "traffic_light")
    net.node("HW_E", x1, cy, "traffic_light")
    local_x = [int(x0) + 200 * k for k in range(10)]
    inner_x = local_x[1:-1]
    stations = [("OFF1_U", 330), ("OFF1_V", 480), ("ON1_M", 820), ("ON1_D", 1000),
                ("OFF2_U", 1130), ("OFF2_V", 1280), ("ON2_M", 1620), ("ON2_D", 1760)]
    lanes = [3, 4, 3, 4, 3, 4, 3, 4, 3]
    for half in ("EB", "WB"):
        def P(x, y, _h=half):
            return (x, y) if _h == "EB" else (2 * cx - x, 2 * cy - y)

        def X(x, _h=half):
            return int(x if _h == "EB" else 2 * cx - x)
        sn = "S" if half == "EB" else "N"
        # local street grid of this side: rows a (near highway) and b
        for x in inner_x:
            for row, yy in (("a", 200.0), ("b", 80.0)):
                net.node(f"{sn}{row}{X(x)}", *P(x, yy))
        for row in ("a", "b"):
            for a, b in zip(inner_x, inner_x[1:], strict=False):
                net.road(f"{sn}{row}{X(a)}", f"{sn}{row}{X(b)}",
                         1, vloc, 3 if row == "a" else 2)
        for x in inner_x[::2]:
            net.road(f"{sn}b{X(x)}", f"{sn}a{X(x)}", 1, vloc, 1)
        # carriageway
        for sid, x in stations:
            net.node(f"{half}_{sid}", *P(x, hy))
        start, end = ("HW_W", "HW_E") if half == "EB" else ("HW_E", "HW_W")
        seq = [start] + [f"{half}_{s}" for s, _ in stations] + [end]
        e = []
        for k, (a, b) in enumerate(zip(seq, seq[1:], strict=False)):
            shape = None
            if k == 0:
                shape = [net.pos(a), P(x0 + 60, hy), net.pos(b)]
            elif k == len(lanes) - 1:
                shape = [net.pos(a), P(x1 - 60, hy), net.pos(b)]
            sp = vend if shape else vh
            e.append(net.edge(a, b, lanes[k], sp, 10, shape, eid=f"{half}_{k}",
                              width=3.5, disallow=hw))
        # ramps: off-ramp V -> local street, on-ramp local street -> M
        ramp = {}
        for sid, lx, off in (("OFF1_V", 650, True), ("ON1_M", 650, False),
                             ("OFF2_V", 1450, True), ("ON2_M", 1450, False)):
            hn, ln = f"{half}_{sid}", f"{sn}a{X(lx)}"
            hx = dict(stations)[sid]
            ry = hy - 3 * 3.5  # ramp lane continues the outermost highway lane
            if off:  # leave tangentially, arrive at the street from upper left
                ctrl = [(hx, ry), (hx + 70, ry), (lx - 35, 250.0), (lx, 200.0)]
            else:  # leave the street to the upper right, join tangentially
                ctrl = [(lx, 200.0), (lx + 35, 250.0), (hx - 70, ry), (hx, ry)]
            net.nodes[ln]["type"] = "traffic_light"  # signalised ramp terminal
            a, b = (hn, ln) if off else (ln, hn)
            ramp[sid] = net.edge(a, b, 1, vramp, 5, [P(*q) for q in bezier(ctrl)],
                                 eid=f"{half}_{sid[:-2]}_ramp")
        # explicit lane connections at the ramp nodes
        for k_in, sid in ((0, "OFF1_V"), (4, "OFF2_V")):
            # U: 3 -> 4 lanes, the deceleration lane opens on the right
            net.conn(e[k_in], e[k_in + 1], 0, 0)
            for li in range(3):
                net.conn(e[k_in], e[k_in + 1], li, li + 1)
            # V: lane 0 is exit-only, lanes 1..3 continue
            net.conn(e[k_in + 1], ramp[sid], 0, 0)
            for li in range(1, 4):
                net.conn(e[k_in + 1], e[k_in + 2], li, li - 1)
        for k_in, sid in ((2, "ON1_M"), (6, "ON2_M")):
            # M: ramp becomes the acceleration lane
            net.conn(ramp[sid], e[k_in + 1], 0, 0)
            for li in range(3):
                net.conn(e[k_in], e[k_in + 1], li, li + 1)
            # D: acceleration lane ends, merging (zipper) into lane 0
            net.conn(e[k_in + 1], e[k_in + 2], 0, 0)
            for li in range(1, 4):
                net.conn(e[k_in + 1], e[k_in + 2], li, li - 1)
            net.nodes[net.edges[e[k_in + 1]]["to"]]["type"] = "zipper"
    # highway ends: junctions tied into both local grids
    for end, x in (("HW_W", int(x0)), ("HW_E", int(x1))):
        nx = x + 200 if x == x0 else x - 200
        for sn, ya, yb in (("S", 200.0, 80.0), ("N", 400.0, 520.0)):
            net.node(f"{sn}a{x}", x, ya)
            net.node(f"{sn}b{x}", x, yb)
            net.road(f"{sn}b{x}", f"{sn}a{x}", 1, vloc, 2)
            net.road(f"{sn}a{x}", f"{sn}a{nx}", 1, vloc, 3)
            net.road(f"{sn}b{x}", f"{sn}b{nx}", 1, vloc, 2)
        net.road(f"Sa{x}", end, 1, vloc, 2)
        net.road(end, f"Na{x}", 1, vloc, 2)
    # local streets passing under the highway (no junction with it)
    for x in (850, 1050):
        net.road(f"Sa{x}", f"Na{x}", 1, vloc, 1)
    return net


def town_rural() -> Net:
    net = Net("icr_rural", sidewalks=False)
    pts = {
        "A": (100, 100, "priority"), "B": (520, 80, "priority_stop"),
        "C": (960, 150, "priority"), "D": (140, 520, "priority_stop"),
        "E": (560, 470, "allway_stop"), "F": (950, 560, "allway_stop"),
        "G": (110, 900, "priority"), "H": (500, 880, "priority_stop"),
        "I": (930, 920, "priority"),
    }
    for nid, (x, y, t) in pts.items():
        net.node(nid, x, y, t)
    roads = [  # a, b, amplitude, waves, lanes, km/h, priority
        ("A", "B", 35, 2, 80, 3), ("B", "C", -40, 1, 80, 3),
        ("A", "D", 30, 1, 70, 2), ("B", "E", -25, 2, 70, 1),
        ("C", "F", 45, 2, 80, 2), ("D", "E", -30, 1, 70, 2),
        ("E", "F", 25, 2, 70, 3), ("D", "G", -35, 2, 70, 2),
        ("E", "H", 30, 1, 70, 1), ("F", "I", -30, 1, 80, 2),
        ("G", "H", 30, 1, 80, 3), ("H", "I", -35, 2, 80, 3),
    ]
    for a, b, amp, waves, kmh, prio in roads:
        shape = curve(net.pos(a), net.pos(b), amp, waves, steps=20)
        net.road(a, b, 1, speed(kmh), prio, shape)
    return net


TOWNS = [town_grid, town_tjunctions, town_arterial, town_roundabout,
         town_highway, town_rural]


# ---------------------------------------------------------------------------
def netconvert_path() -> str:
    import sumo
    return os.path.join(sumo.SUMO_HOME, "bin", "netconvert")


HEADER_RE = re.compile(r"<!--.*?-->\s*", re.S)


def build(net: Net, out_dir: str, tmp: str) -> str:
    files = net.write(tmp)
    raw = os.path.join(tmp, net.name + ".net.xml")
    cmd = [netconvert_path()] + files + COMMON_OPTIONS
    if net.sidewalks:
        cmd += PED_OPTIONS
    cmd += ["--output-file", raw]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        sys.stderr.write(res.stdout + res.stderr)
        raise SystemExit(f"netconvert failed for {net.name}")
    for line in (res.stdout + res.stderr).splitlines():
        if line.strip():
            print(f"  [{net.name}] {line}")
    with open(raw, encoding="utf-8") as f:
        text = f.read()
    # drop the header comment (date, option paths) so output is reproducible
    head, sep, rest = text.partition("<net ")
    head = HEADER_RE.sub("", head)
    text = head + sep + rest
    out = os.path.join(out_dir, net.name + ".net.xml")
    with open(out, "w", encoding="utf-8", newline="\n") as f:
        f.write(text)
    return out


# ---------------------------------------------------------------------------
def report(path: str) -> dict:
    root = ET.parse(path).getroot()
    edges = [e for e in root.findall("edge") if e.get("function") is None]
    crossings = [e for e in root.findall("edge") if e.get("function") == "crossing"]
    jtypes = Counter(j.get("type") for j in root.findall("junction")
                     if j.get("type") != "internal")
    # passenger connectivity over normal edges
    lane_allow = {}
    for e in edges:
        for ln in e.findall("lane"):
            allow, dis = ln.get("allow"), ln.get("disallow")
            ok = (allow is None or "passenger" in allow.split()) and \
                (dis is None or "passenger" not in dis.split())
            lane_allow[ln.get("id")] = ok
    car_edges = sorted({e.get("id") for e in edges
                        if any(lane_allow[ln.get("id")] for ln in e.findall("lane"))})
    succ = {e: set() for e in car_edges}
    pred = {e: set() for e in car_edges}
    for c in root.findall("connection"):
        f, t = c.get("from"), c.get("to")
        fl, tl = f"{f}_{c.get('fromLane')}", f"{t}_{c.get('toLane')}"
        if f in succ and t in succ and lane_allow[fl] and lane_allow[tl]:
            succ[f].add(t)
            pred[t].add(f)

    def reach(start, g):
        seen, dq = {start}, deque([start])
        while dq:
            for n in g[dq.popleft()]:
                if n not in seen:
                    seen.add(n)
                    dq.append(n)
        return seen

    s0 = car_edges[0]
    strong = len(reach(s0, succ)) == len(car_edges) == len(reach(s0, pred))
    loc = root.find("location")
    return {
        "size_kB": os.path.getsize(path) / 1024.0,
        "normal_edges": len(edges),
        "car_edges": len(car_edges),
        "junctions": dict(sorted(jtypes.items())),
        "crossings": len(crossings),
        "roundabouts": len(root.findall("roundabout")),
        "max_lanes": max(len(e.findall("lane")) for e in edges),
        "max_car_lanes": max(sum(lane_allow[ln.get("id")] for ln in e.findall("lane"))
                             for e in edges),
        "convBoundary": loc.get("convBoundary"),
        "netOffset": loc.get("netOffset"),
        "strongly_connected": strong,
    }


def main(argv=None) -> int:
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(os.path.dirname(here), "networks"))
    ap.add_argument("--report", action="store_true",
                    help="print statistics and check connectivity")
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    ok = True
    with tempfile.TemporaryDirectory(prefix="icr_nets_") as tmp:
        for make in TOWNS:
            net = make()
            path = build(net, args.out, tmp)
            print(f"wrote {path}")
            if args.report:
                r = report(path)
                ok &= r["strongly_connected"]
                for k, v in r.items():
                    print(f"    {k:<18} {v}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
