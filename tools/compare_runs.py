"""Compare two ``icrsumo evaluate`` out folders episode by episode (the redesign guard).

Every stored row (scores, termination, infractions, attempts, message) and every episode log
(decompressed JSON) of OLD is compared with NEW's, and so are the report files
(summary.json, results.*, episodes.csv, leaderboard/*.json). For each episode that differs the
report says which parts differ; when only events of the kinds given by ``--explained`` differ
(default: collision_static, the roadside check) while every per-step column is identical, the
episode is listed with its old and new events of those kinds. Any other difference is a
failure (exit status 1).

    python tools/compare_runs.py OLD_OUT NEW_OUT [--explained collision_static] [--json FILE]
                                 [--roadside-causes] [--effect]

``--effect`` instead prints what a change of the closed loop's rules did to a run (the same
command run by two icrsumo versions, docs/scoring.md "Loop versions"): per agent and family,
over the episodes done in both, the mean DS, RC and IS before → after, how many drove the same
trajectory (the ego's logged x, y equal over the steps both logs hold), how many changed DS, and
the penalised infractions Leaderboard 1.0 charges (static-layout collisions as CollisionTest
counts them, red lights, stop signs) before → after; exit status 0.

``--roadside-causes`` classifies every roadside event that is in one run and not the other
(no event of the other run within 0.5 s) from the ego's pose at that time on the route's
network: the ego's corners on the old BEV raster's drivable canvas (0.5 m per pixel, lanes
only) and on the polygons of :mod:`icrsumo.sim.drivable` (lanes and junction carriageways):
``one excursion for the other run`` (the other run's test had the ego off the road on the
step before: one continuous excursion that this run's test split in two), ``junction area`` (a
corner off every lane but on a junction's carriageway), ``lane edge`` (a corner beyond a lane's
edge), with the largest distance (m) of an off corner from the polygons.
"""

from __future__ import annotations

import argparse
import json
import sqlite3
import statistics
import sys
import zlib
from collections import defaultdict
from pathlib import Path

REPORT_FILES = ("summary.json", "results.md", "results.csv", "results.tex", "episodes.csv")


def _rows(out: Path) -> dict[tuple, dict]:
    db = sqlite3.connect(f"file:{out / 'results.sqlite'}?mode=ro", uri=True)
    db.row_factory = sqlite3.Row
    rows = {}
    for r in db.execute("SELECT * FROM episodes"):
        d = dict(r)
        blob = d.pop("log")
        d["log"] = json.loads(zlib.decompress(blob).decode("utf-8")) if blob else None
        rows[(d["agent"], d["route_id"], d["family"], d["k"], d["seed"])] = d
    db.close()
    return rows


def _events_of(log: dict | None, kinds: set[str], keep: bool) -> list:
    if not log:
        return []
    return [e for e in log["events"] if (e[0] in kinds) == keep]


def compare(old: Path, new: Path, explained: set[str]) -> dict:
    a, b = _rows(old), _rows(new)
    out = {"episodes_old": len(a), "episodes_new": len(b), "identical": 0,
           "missing_in_new": sorted(map(list, set(a) - set(b))),
           "extra_in_new": sorted(map(list, set(b) - set(a))), "explained": [], "unexplained": []}
    for key in sorted(set(a) & set(b)):
        ra, rb = a[key], b[key]
        if ra == rb:
            out["identical"] += 1
            continue
        la, lb = ra["log"], rb["log"]
        same_steps = bool(la and lb and la["steps"] == lb["steps"])
        same_other_events = _events_of(la, explained, False) == _events_of(lb, explained, False)
        same_header = bool(la and lb and all(la[k] == lb[k] for k in la if k not in ("steps", "events")))
        entry = {
            "episode": list(key), "same_steps": same_steps, "same_other_events": same_other_events,
            "same_log_header": same_header,
            "old_events": _events_of(la, explained, True), "new_events": _events_of(lb, explained, True),
            "old": {k: ra[k] for k in ("ds", "is_", "rc", "termination", "infractions")},
            "new": {k: rb[k] for k in ("ds", "is_", "rc", "termination", "infractions")},
        }
        ok = same_steps and same_other_events and same_header and entry["old"]["rc"] == entry["new"]["rc"] \
            and entry["old"]["termination"] == entry["new"]["termination"]
        out["explained" if ok else "unexplained"].append(entry)
    files = {}
    for name in REPORT_FILES:
        pa, pb = old / name, new / name
        files[name] = pa.is_file() and pb.is_file() and pa.read_bytes() == pb.read_bytes()
    for pa in sorted((old / "leaderboard").glob("*.json")):
        pb = new / "leaderboard" / pa.name
        files[f"leaderboard/{pa.name}"] = pb.is_file() and pa.read_bytes() == pb.read_bytes()
    out["files_identical"] = files
    return out


def roadside_causes(old: Path, res: dict) -> list[dict]:
    """Classify the unmatched roadside events of ``res['explained']`` (see the docstring)."""
    import math

    import numpy as np
    import shapely
    from shapely.geometry import Point

    from icrsumo.render import BevRenderer, BevSpec
    from icrsumo.sim.drivable import DrivableArea, drivable_area, lane_polygons, polygonal
    from icrsumo.sim.sensors import footprint_corners
    from icrsumo.world.dynamics import EgoState
    from icrsumo.world.networks import load_net
    from icrsumo.world.scenario import find_scenarios, read_scenario

    scenarios = {sc.route_id: sc for sc in (read_scenario(d) for d in find_scenarios(old / "scenarios"))}
    cache: dict = {}
    rows = _rows(old)
    out = []
    for e in res["explained"]:
        key = tuple(e["episode"])
        sc = scenarios[key[1]]
        if sc.route_id not in cache:
            net = load_net(sc.net)
            lanes_only = DrivableArea(polygonal(shapely.union_all(lane_polygons(net))))
            cache[sc.route_id] = (BevRenderer(net, BevSpec()), drivable_area(net), lanes_only)
        raster, area, lanes_only = cache[sc.route_id]
        size = (sc.ego.length, sc.ego.width)
        steps = rows[key]["log"]["steps"]
        for side, mine, other in (("old", e["old_events"], e["new_events"]),
                                  ("new", e["new_events"], e["old_events"])):
            for ev in mine:
                if any(abs(ev[1] - o[1]) <= 0.5 for o in other):
                    continue
                i = min(range(len(steps["t"])), key=lambda j, t=ev[1]: abs(steps["t"][j] - t))
                st = EgoState(steps["x"][i], steps["y"][i], steps["yaw"][i])
                corners = footprint_corners(st, size)
                on_raster = raster.drivable_at(corners)
                on_poly = area.contains_xy(corners)
                on_lanes = lanes_only.contains_xy(corners)
                geom = area.geometry
                dists = sorted((geom.distance(Point(c)) for c, ok in zip(corners, on_poly) if not ok),
                               reverse=True)
                off_d = dists[0] if dists else 0.0
                second = dists[1] if len(dists) > 1 else 0.0
                prev = footprint_corners(EgoState(steps["x"][i - 1], steps["y"][i - 1], steps["yaw"][i - 1]),
                                         size) if i > 0 else corners
                other_off_before = int((~(area.contains_xy(prev) if side == "old" else
                                          raster.drivable_at(prev))).sum()) >= 2
                if other_off_before:
                    cause = "one excursion for the other run"
                elif bool(np.any(on_poly & ~on_lanes & ~on_raster)):
                    cause = "junction area"
                else:
                    cause = "lane edge"
                out.append({"episode": list(key), "run": side, "t": ev[1], "cause": cause,
                            "corners_off_raster": int((~on_raster).sum()),
                            "corners_off_polygons": int((~on_poly).sum()),
                            "max_off_m": round(off_d, 3) if math.isfinite(off_d) else None,
                            "second_off_m": round(second, 3)})
    return out


def _fmt_events(events: list) -> str:
    return "; ".join(f"t={e[1]:.2f} s at {e[2]:.1f} m ({e[4]:.1f}, {e[5]:.1f})" for e in events) or "none"


def markdown(res: dict) -> str:
    lines = [f"episodes: {res['episodes_old']} old, {res['episodes_new']} new; byte-identical rows and "
             f"logs: {res['identical']}; changed only in the explained events: {len(res['explained'])}; "
             f"other changes: {len(res['unexplained'])}; missing: {len(res['missing_in_new'])}; "
             f"extra: {len(res['extra_in_new'])}", ""]
    same = [k for k, v in res["files_identical"].items() if v]
    diff = [k for k, v in res["files_identical"].items() if not v]
    lines.append(f"report files identical: {', '.join(same) or 'none'}; "
                 f"different: {', '.join(diff) or 'none'}")
    if res["explained"]:
        lines += ["", "| agent | route | family | k | DS old → new | IS old → new | old roadside events | "
                  "new roadside events |", "|---|---|---|---:|---:|---:|---|---|"]
        for e in res["explained"]:
            ag, rid, fam, k, _ = e["episode"]
            lines.append(f"| {ag} | {rid} | {fam} | {k} | {e['old']['ds']:.1f} → {e['new']['ds']:.1f} | "
                         f"{e['old']['is_']:.3f} → {e['new']['is_']:.3f} | {_fmt_events(e['old_events'])} | "
                         f"{_fmt_events(e['new_events'])} |")
    for e in res["unexplained"]:
        lines.append(f"UNEXPLAINED {e['episode']}: steps same {e['same_steps']}, other events same "
                     f"{e['same_other_events']}, header same {e['same_log_header']}, "
                     f"old {e['old']}, new {e['new']}")
    return "\n".join(lines)


#: the penalised kinds --effect counts
KINDS = ("collision_static", "red_light", "stop_sign")


def charged(log) -> dict[str, int]:
    """Counts of the penalised static collisions, red lights and stop signs of one log."""
    from icrsumo.scoring.lb1 import counted_collisions

    out = dict.fromkeys(KINDS, 0)
    for e in counted_collisions(log):
        if e.kind == "collision_static":
            out[e.kind] += 1
    for e in log.events:
        if e.kind in ("red_light", "stop_sign"):
            out[e.kind] += 1
    return out


def _key(r) -> tuple[str, str, str, int, int]:
    return r.agent, r.route_id, r.family, r.k, r.seed


def effect(before: Path, after: Path) -> list[dict]:
    """One row per (agent, family) with paired episodes (``--effect``)."""
    from icrsumo.results.store import ResultStore

    with ResultStore(before / "results.sqlite", readonly=True) as a, \
            ResultStore(after / "results.sqlite", readonly=True) as b:
        old = {_key(r): r for r in a.records() if r.status == "done"}
        new = {_key(r): r for r in b.records() if r.status == "done"}
        groups: dict[tuple[str, str], list] = defaultdict(list)
        for key in sorted(old.keys() & new.keys()):
            ra, rb = old[key], new[key]
            la, lb = a.episode_log(*key), b.episode_log(*key)
            n = min(len(la.x), len(lb.x))
            same = la.x[:n] == lb.x[:n] and la.y[:n] == lb.y[:n]
            groups[(ra.agent, ra.family)].append((ra, rb, same, charged(la), charged(lb)))
    rows = []
    for (agent, family), items in sorted(groups.items()):
        row = {"agent": agent, "family": family, "n": len(items),
               "same_path": sum(s for _, _, s, _, _ in items),
               "ds_changed": sum(abs(ra.ds - rb.ds) > 1e-9 for ra, rb, _, _, _ in items)}
        for col, attr in (("ds", "ds"), ("rc", "rc"), ("is", "is_")):
            row[col] = (statistics.fmean(getattr(ra, attr) for ra, _, _, _, _ in items),
                        statistics.fmean(getattr(rb, attr) for _, rb, _, _, _ in items))
        for kind in KINDS:
            row[kind] = (sum(ca[kind] for *_, ca, _ in items), sum(cb[kind] for *_, cb in items))
        rows.append(row)
    return rows

def effect_markdown(rows: list[dict]) -> str:
    """The ``--effect`` table."""
    head = "| agent | family | n | same path | DS changed | DS | RC | IS | static | red light | stop sign |"
    lines = [head, "|---|---|---:|---:|---:|---|---|---|---|---|---|"]
    for r in rows:
        ds, rc, is_ = r["ds"], r["rc"], r["is"]
        kinds = " | ".join(f"{r[k][0]} → {r[k][1]}" for k in KINDS)
        lines.append(f"| {r['agent']} | {r['family']} | {r['n']} | {r['same_path']} | {r['ds_changed']} | "
                     f"{ds[0]:.1f} → {ds[1]:.1f} | {rc[0]:.1f} → {rc[1]:.1f} | "
                     f"{is_[0]:.3f} → {is_[1]:.3f} | {kinds} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("old", type=Path)
    ap.add_argument("new", type=Path)
    ap.add_argument("--explained", action="append", default=None,
                    help="event kinds whose changes are expected (default collision_static)")
    ap.add_argument("--json", type=Path, default=None, help="also write the full comparison here")
    ap.add_argument("--roadside-causes", action="store_true",
                    help="classify the roadside events found by one run only (needs the networks)")
    ap.add_argument("--effect", action="store_true",
                    help="print the per agent and family effect of a change of the loop's rules instead")
    args = ap.parse_args(argv)
    if args.effect:
        print(effect_markdown(effect(args.old, args.new)))
        return 0
    res = compare(args.old, args.new, set(args.explained or ["collision_static"]))
    print(markdown(res))
    if args.roadside_causes:
        from collections import Counter

        res["roadside_causes"] = causes = roadside_causes(args.old, res)
        print("\nroadside events found by one run only:")
        for (run, cause), n in sorted(Counter((c["run"], c["cause"]) for c in causes).items()):
            mine = [c for c in causes if c["run"] == run and c["cause"] == cause]
            far = sorted(c["max_off_m"] for c in mine)
            second = sorted(c["second_off_m"] for c in mine)
            print(f"- {run} run only, {cause}: {n} events; distance of the farthest / second-farthest "
                  f"corner off the polygons: median {far[len(far) // 2]:.2f} / "
                  f"{second[len(second) // 2]:.2f} m, "
                  f"max {far[-1]:.2f} / {second[-1]:.2f} m")
    if args.json:
        args.json.write_text(json.dumps(res, indent=1) + "\n", encoding="utf-8")
    bad = res["unexplained"] or res["missing_in_new"] or res["extra_in_new"]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
