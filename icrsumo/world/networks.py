"""SUMO road networks: loading (sumolib), lane geometry, the passenger-car edge graph,
CARLA<->SUMO coordinates and OpenDRIVE conversion with a cache.

Coordinates are SUMO's (right-handed, metres). Headings are radians counter-clockwise from +x.
"""

from __future__ import annotations

import hashlib
import heapq
import math
import os
import subprocess
import tempfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from icrsumo.core.errors import Field, InputError
from icrsumo.core.fsio import sha256_file, strip_header_comments, write_atomic
from icrsumo.core.resources import sumo_binary, sumo_home

from .routes import check_xml_file

#: vehicle class of the ego and of background cars
EGO_VCLASS = "passenger"

#: netconvert options for OpenDRIVE files made by CARLA: driving lanes only, no U-turns,
#: CARLA's own curve resolution and radius fix, original ids kept as lane parameters
XODR_OPTIONS = (
    "--opendrive.import-all-lanes", "false",
    "--no-turnarounds", "true",
    "--junctions.join", "true",
    "--opendrive.curve-resolution", "1",
    "--geometry.min-radius.fix", "true",
    "--output.original-names", "true",
)


@dataclass(frozen=True)
class Connection:
    """A passenger-car connection between two normal edges: lane indices, first internal
    (``via``) lane, SUMO direction (s, l, r, t, L, R) and static state (M major, m minor,
    s stop, w all-way stop, o traffic light), the controlling traffic light and link index
    (or "" / -1), and every internal lane the connection runs through (``via_chain``)."""

    from_edge: str
    to_edge: str
    from_lane: int
    to_lane: int
    via: str
    via_length: float
    direction: str
    state: str = ""
    tls: str = ""
    link_index: int = -1
    via_chain: tuple[str, ...] = ()


def polyline_cumlen(shape: np.ndarray) -> np.ndarray:
    """Arc length (m) at each vertex of the polyline ``shape`` ((N, 2) m): (N,), from 0."""
    seg = np.hypot(*np.diff(shape, axis=0).T) if len(shape) > 1 else np.zeros(0)
    return np.concatenate([[0.0], np.cumsum(seg)])


class RoadNet:
    """A loaded SUMO network with the queries the converter and the simulator need."""

    def __init__(self, path: Path) -> None:
        import sumolib  # sumolib's net reader; pure Python

        self.path = Path(path)
        check_xml_file(self.path, "network file", f"check the path or {Field('net')}")
        try:
            net = sumolib.net.readNet(str(self.path), withInternal=True)
            self._init(net)
        except InputError:
            raise
        except Exception as err:  # sumolib and a half-formed net raise assorted errors
            text = " ".join(str(err).split())
            raise InputError(
                self.path, "", f"not a readable SUMO network ({type(err).__name__}: {text[:120]})",
                "give a .net.xml written by netconvert",
            ) from None

    def _init(self, net) -> None:
        self.sha256 = sha256_file(self.path)
        off = net.getLocationOffset()
        #: SUMO netOffset (x, y) in m: x_sumo = x_carla + off_x, y_sumo = -y_carla + off_y
        self.offset = (float(off[0]), float(off[1]))
        if not all(math.isfinite(v) and abs(v) <= 1e9 for v in self.offset):
            raise InputError(self.path, "<location netOffset>",
                             f"offset {off} is not finite (or beyond 1e9 m)",
                             "give a .net.xml written by netconvert")
        self._net = net
        self.edge_length: dict[str, float] = {}
        self.edge_speed: dict[str, float] = {}
        self.passenger_lanes: dict[str, tuple[int, ...]] = {}
        self.edge_to_node: dict[str, str] = {}
        self.node_type: dict[str, str] = {}
        self.lane_shape: dict[str, np.ndarray] = {}
        self.lane_length: dict[str, float] = {}
        self.connections: dict[tuple[str, str], tuple[Connection, ...]] = {}
        self.successors: dict[str, tuple[str, ...]] = {}
        self.via_edges: dict[str, tuple[str, str]] = {}
        self.roundabout_edges: frozenset[str] = frozenset(
            e for r in net.getRoundabouts() for e in r.getEdges()
        )
        self.has_sidewalks = False
        self._cum_cache: dict[str, np.ndarray] = {}
        self._via_min: dict[tuple[str, str], float] = {}
        self._choice: dict[str, bool] = {}
        self._arms: dict[str, set[str]] = {}
        #: nodes with pedestrian crossings
        self.crossing_nodes: frozenset[str] = frozenset()
        self._load(net)
        self._build_segments()

    # ----------------------------------------------------------------- loading
    def _load(self, net) -> None:
        for node in net.getNodes():
            self.node_type[node.getID()] = node.getType()
        crossings = set()
        for edge in net.getEdges(withInternal=True):
            if edge.getFunction() == "crossing":
                crossings.add(edge.getFromNode().getID())
            for lane in edge.getLanes():
                if lane.allows(EGO_VCLASS):
                    self.lane_shape[lane.getID()] = np.asarray(lane.getShape(), dtype=float)[:, :2]
                    self.lane_length[lane.getID()] = float(lane.getLength())
            if edge.getFunction() != "":
                continue
            eid = edge.getID()
            lanes = edge.getLanes()
            if any(ln.allows("pedestrian") and not ln.allows(EGO_VCLASS) for ln in lanes):
                self.has_sidewalks = True
            car = tuple(ln.getIndex() for ln in lanes if ln.allows(EGO_VCLASS))
            if not car:
                continue
            self.passenger_lanes[eid] = car
            a, b = edge.getFromNode().getID(), edge.getToNode().getID()
            self._arms.setdefault(a, set()).add(b)
            self._arms.setdefault(b, set()).add(a)
            self.edge_length[eid] = float(edge.getLength())
            self.edge_speed[eid] = float(edge.getSpeed())
            self.edge_to_node[eid] = edge.getToNode().getID()
        self.crossing_nodes = frozenset(crossings)
        for eid in sorted(self.passenger_lanes):
            edge = net.getEdge(eid)
            conns: dict[str, list[Connection]] = {}
            for to_edge, clist in edge.getOutgoing().items():
                tid = to_edge.getID()
                if tid not in self.passenger_lanes:
                    continue
                for c in clist:
                    fl, tl = c.getFromLane(), c.getToLane()
                    if not (fl.allows(EGO_VCLASS) and tl.allows(EGO_VCLASS)):
                        continue
                    via = c.getViaLaneID() or ""
                    chain = []
                    lane_id = via
                    while lane_id and lane_id not in chain and len(chain) < 8:
                        chain.append(lane_id)
                        outs = net.getLane(lane_id).getOutgoing()
                        lane_id = (outs[0].getViaLaneID() or "") if outs else ""
                    via_len = sum(self.lane_length.get(v, 0.0) for v in chain)
                    conns.setdefault(tid, []).append(
                        Connection(eid, tid, fl.getIndex(), tl.getIndex(), via, via_len,
                                   c.getDirection(), c.getState() or "", c.getTLSID() or "",
                                   int(c.getTLLinkIndex()), tuple(chain))
                    )
                    for v in chain:
                        self.via_edges.setdefault(v, (eid, tid))
            for tid, clist in conns.items():
                self.connections[(eid, tid)] = tuple(
                    sorted(clist, key=lambda c: (c.from_lane, c.to_lane))
                )
                self._via_min[(eid, tid)] = min(c.via_length for c in clist)
            self.successors[eid] = tuple(sorted(conns))

    def _build_segments(self) -> None:
        """Flatten every passenger lane into segment arrays for vectorised projection."""
        a, b, lane_idx, start = [], [], [], []
        self._lane_ids = sorted(self.lane_shape)
        for i, lid in enumerate(self._lane_ids):
            shape = self.lane_shape[lid]
            if len(shape) < 2:
                continue
            cum = polyline_cumlen(shape)
            a.append(shape[:-1])
            b.append(shape[1:])
            lane_idx.append(np.full(len(shape) - 1, i))
            start.append(cum[:-1])
        if not a:
            raise InputError(self.path, "", "has no lanes that passenger cars may use",
                             "give a road network with car lanes")
        self._seg_a = np.concatenate(a)
        self._seg_b = np.concatenate(b)
        bad = ~(np.isfinite(self._seg_a).all(axis=1) & np.isfinite(self._seg_b).all(axis=1)
                & (np.abs(self._seg_a) <= 1e8).all(axis=1) & (np.abs(self._seg_b) <= 1e8).all(axis=1))
        if bad.any():
            lane = self._lane_ids[int(np.concatenate(lane_idx)[int(np.argmax(bad))])]
            raise InputError(self.path, f"lane {lane}", "shape holds a non-finite or huge coordinate",
                             "give a .net.xml written by netconvert")
        self._seg_lane = np.concatenate(lane_idx)
        self._seg_start = np.concatenate(start)
        self._seg_ab = self._seg_b - self._seg_a
        self._seg_ab2 = np.maximum((self._seg_ab * self._seg_ab).sum(axis=1), 1e-12)
        self._seg_lo = np.minimum(self._seg_a, self._seg_b)
        self._seg_hi = np.maximum(self._seg_a, self._seg_b)

    # ----------------------------------------------------------------- geometry
    def node_arms(self, node: str) -> int:
        """Number of distinct neighbouring nodes joined to ``node`` by car edges (roads met)."""
        return len(self._arms.get(node, set()) - {node})

    @property
    def lane_km(self) -> float:
        """Total length of passenger-car lanes on normal edges (km)."""
        return sum(
            self.lane_length[f"{e}_{i}"] for e, idx in self.passenger_lanes.items() for i in idx
        ) / 1000.0

    @property
    def edge_km(self) -> float:
        """Total length of normal edges that cars may use (km)."""
        return sum(self.edge_length.values()) / 1000.0

    @property
    def sumolib_net(self):
        """The underlying ``sumolib.net.Net``."""
        return self._net

    def to_sumo(self, x: float, y: float, yaw_deg: float | None, coords: str):
        """File coordinates -> SUMO (x, y in m, heading in rad or None).

        ``coords='sumo'``: x, y as given, yaw in degrees counter-clockwise from +x.
        ``coords='carla'``: CARLA's left-handed frame: x + off_x, -y + off_y, heading -yaw.
        """
        if coords == "carla":
            ox, oy = self.offset
            heading = None if yaw_deg is None else -math.radians(yaw_deg)
            return x + ox, -y + oy, heading
        return x, y, None if yaw_deg is None else math.radians(yaw_deg)

    def to_file_coords(self, x: float, y: float, heading: float, coords: str):
        """Inverse of :meth:`to_sumo`: SUMO pose -> (x, y, yaw in degrees) in file coordinates."""
        if coords == "carla":
            ox, oy = self.offset
            return x - ox, -(y - oy), -math.degrees(heading)
        return x, y, math.degrees(heading)

    def _cum(self, lane: str) -> np.ndarray:
        """Cumulative shape length (m) at each point of a lane (cached)."""
        cum = self._cum_cache.get(lane)
        if cum is None:
            cum = self._cum_cache[lane] = polyline_cumlen(self.lane_shape[lane])
        return cum

    def lane_pose(self, lane: str, pos: float) -> tuple[float, float, float]:
        """World (x, y, heading) at lane position ``pos`` (m from the lane start)."""
        shape = self.lane_shape[lane]
        cum = self._cum(lane)
        total = float(cum[-1])
        s = min(max(pos * total / max(self.lane_length[lane], 1e-9), 0.0), total)
        k = min(max(int(np.searchsorted(cum, s, side="right")) - 1, 0), len(shape) - 2)
        x0, y0 = shape[k]
        x1, y1 = shape[k + 1]
        seg_len = max(float(cum[k + 1] - cum[k]), 1e-9)
        f = (s - float(cum[k])) / seg_len
        return float(x0 + (x1 - x0) * f), float(y0 + (y1 - y0) * f), math.atan2(y1 - y0, x1 - x0)

    def lane_slice(self, lane: str, a: float, b: float) -> np.ndarray:
        """Lane centre line between lane positions a <= b (m), shape (N, 2)."""
        shape = self.lane_shape[lane]
        cum = self._cum(lane)
        total = float(cum[-1])
        scale = total / max(self.lane_length[lane], 1e-9)
        sa, sb = min(max(a * scale, 0.0), total), min(max(b * scale, 0.0), total)
        inner = shape[(cum > sa) & (cum < sb)]
        pa = self.lane_pose(lane, a)[:2]
        pb = self.lane_pose(lane, b)[:2]
        return np.vstack([pa, inner, pb])

    def project(self, x: float, y: float, radius: float) -> list[tuple[str, float, float, float]]:
        """Passenger lanes within ``radius`` m of (x, y): (lane, pos m, distance m, heading rad),
        one entry per lane (its closest point), nearest first."""
        p = np.array([x, y])
        # only the segments whose bounding box comes within the radius (a margin for rounding)
        r = radius + 1e-6
        lo, hi = self._seg_lo, self._seg_hi
        box = np.nonzero((lo[:, 0] <= x + r) & (hi[:, 0] >= x - r)
                         & (lo[:, 1] <= y + r) & (hi[:, 1] >= y - r))[0]
        a, ab, ab2 = self._seg_a[box], self._seg_ab[box], self._seg_ab2[box]
        t = np.clip(((p - a) * ab).sum(axis=1) / ab2, 0.0, 1.0)
        closest = a + ab * t[:, None]
        dist = np.hypot(*(closest - p).T)
        near = np.nonzero(dist <= radius)[0]
        best: dict[int, int] = {}
        for s in near[np.argsort(dist[near], kind="stable")]:
            best.setdefault(int(self._seg_lane[box[s]]), int(s))
        out = []
        for li, s in best.items():
            lid = self._lane_ids[li]
            shape_len = self._cum(lid)[-1]
            s_along = self._seg_start[box[s]] + t[s] * math.sqrt(ab2[s])
            pos = s_along * self.lane_length[lid] / max(shape_len, 1e-9)
            out.append((lid, float(pos), float(dist[s]), math.atan2(ab[s, 1], ab[s, 0])))
        out.sort(key=lambda c: (c[2], c[0]))
        return out

    # ----------------------------------------------------------------- graph
    def enters_roundabout(self, from_edge: str, to_edge: str) -> bool:
        """Whether the junction from ``from_edge`` to ``to_edge`` enters a roundabout."""
        return to_edge in self.roundabout_edges and from_edge not in self.roundabout_edges

    def offers_choice(self, edge: str) -> bool:
        """Whether the junction at the end of ``edge`` leads onto more than one road (U-turns
        not counted)."""
        out = self._choice.get(edge)
        if out is None:
            out = self._choice[edge] = sum(
                1 for s in self.successors[edge]
                if any(c.direction != "t" for c in self.connections[(edge, s)])) > 1
        return out

    def via_length(self, from_edge: str, to_edge: str) -> float:
        """Shortest junction-internal length (m) between two connected edges."""
        return self._via_min[(from_edge, to_edge)]

    def shortest_paths(
        self, source: str, source_pos: float, targets: set[str]
    ) -> dict[str, tuple[float, tuple[str, ...]]]:
        """Dijkstra from lane position ``source_pos`` on edge ``source`` to the START of each
        target edge: target -> (distance m, edges strictly between source and target).

        The source edge itself is a valid target only by driving a loop back to it.
        """
        rest = self.edge_length[source] - source_pos
        dist: dict[str, float] = {}
        pred: dict[str, str] = {}
        heap = []
        via = self._via_min
        for n in self.successors.get(source, ()):
            heapq.heappush(heap, (rest + via[(source, n)], n, source))
        remaining = set(targets)
        while heap and remaining:
            d, e, p = heapq.heappop(heap)
            if e in dist:
                continue
            dist[e] = d
            pred[e] = p
            remaining.discard(e)
            base = d + self.edge_length[e]
            for n in self.successors.get(e, ()):
                if n not in dist:
                    heapq.heappush(heap, (base + via[(e, n)], n, e))
        out = {}
        for t in targets:
            if t not in dist:
                continue
            chain = []
            e = pred[t]
            while e != source:
                chain.append(e)
                e = pred[e]
            out[t] = (dist[t], tuple(reversed(chain)))
        return out


@lru_cache(maxsize=16)
def _load_cached(path: str, mtime_ns: int, size: int) -> RoadNet:
    return RoadNet(Path(path))


def load_net(path: Path) -> RoadNet:
    """Load (and cache per process) the network at ``path``."""
    check_xml_file(Path(path), "network file", f"check the path or {Field('net')}")
    p = Path(path).resolve()
    st = p.stat()
    return _load_cached(str(p), st.st_mtime_ns, st.st_size)


def convert_xodr(xodr: Path, cache_dir: Path) -> Path:
    """Convert an OpenDRIVE file with netconvert once; later calls reuse the cached net.

    The cache key is the SHA-256 of the file's bytes and of the netconvert options.
    """
    xodr = Path(xodr)
    check_xml_file(xodr, "OpenDRIVE file", f"check the {Field('xodr')} path")
    key = hashlib.sha256(
        bytes.fromhex(sha256_file(xodr)) + " ".join(XODR_OPTIONS).encode()
    ).hexdigest()[:16]
    out = Path(cache_dir) / f"{xodr.stem}-{key}.net.xml"
    if out.is_file():
        return out
    env = dict(os.environ, PROJ_LIB=str(sumo_home() / "data" / "proj"))
    # netconvert writes into a private folder: nothing lands in cache_dir unless it succeeds
    with tempfile.TemporaryDirectory(prefix="icrsumo-netconvert-") as scratch:
        tmp = Path(scratch) / "out.net.xml"
        proc = subprocess.run(
            [sumo_binary("netconvert"), "--opendrive-files", str(xodr), *XODR_OPTIONS,
             "--output-file", str(tmp), "--no-warnings", "true"],
            capture_output=True, text=True, env=env,
        )
        if proc.returncode != 0 or not tmp.is_file():
            msg = (proc.stderr or proc.stdout).strip().splitlines()
            last = " ".join(msg[-1].split())[:200] if msg else "no output"
            raise InputError(xodr, "", f"netconvert failed: {last}",
                             "check that the file is valid OpenDRIVE")
        text = tmp.read_text(encoding="utf-8")
    write_atomic(out, strip_header_comments(text))
    return out
