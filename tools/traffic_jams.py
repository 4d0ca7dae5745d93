"""Does background traffic jam by itself? For each bundled town, the background traffic that
``convert-routes`` writes (same generator, seed and level) is run in SUMO with no ego for
``--minutes`` (default 20) and sampled every 10 s: vehicles in the network, vehicles halted
(speed < 0.1 m/s), vehicles that have waited more than 60 s, and teleports so far. Traffic that
never jams keeps the halted count bounded; a gridlock shows as a halted count that grows with
the fleet and never falls (``../shared/carla/FINDINGS-2.md``, class F).

    python tools/traffic_jams.py [--level normal] [--minutes 20] [--seed 2026] [--towns A,B]
                                 [--uncapped] [--json FILE]

Prints one row per town: peak and final vehicles, peak and final halted, the share of samples
in the last 10 minutes with more than a quarter of the fleet halted, teleports.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from icrsumo.core.resources import bundled_towns
from icrsumo.world.convert import sumocfg_xml
from icrsumo.world.networks import load_net
from icrsumo.world.traffic import fleet_cap, make_traffic

SAMPLE_S = 10.0
WAITED_S = 60.0


def run_town(town: str, level: str, minutes: float, seed: int, cap: bool = True) -> dict:
    """Run ``town``'s background traffic with no ego; the samples (lists over time, every
    :data:`SAMPLE_S` s) and a summary. ``cap``: with the fleet cap scenarios get
    (:func:`icrsumo.world.traffic.fleet_cap`); without it, insertions are never held back."""
    import libsumo as ls

    net = load_net(bundled_towns()[town])
    end = minutes * 60.0
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        traffic = make_traffic(net.path, net.lane_km, net.edge_km, net.has_sidewalks, out, seed, level,
                               end + 60)
        files = [f for f in (traffic.vehicles, traffic.pedestrians) if f]
        max_vehicles = fleet_cap(town, net.lane_km, level) if cap else -1
        cfg = sumocfg_xml(str(net.path), files, seed, end, max_vehicles)
        (out / "s.sumocfg").write_text(cfg, encoding="utf-8")
        ls.start(["sumo", "-c", str(out / "s.sumocfg"), "--no-step-log", "true"])
        try:
            samples = {"t": [], "vehicles": [], "halted": [], "waited": [], "teleports": []}
            teleports = 0
            next_sample = SAMPLE_S
            while ls.simulation.getTime() < end:
                ls.simulationStep()
                teleports += ls.simulation.getStartingTeleportNumber()
                t = ls.simulation.getTime()
                if t + 1e-6 >= next_sample:
                    next_sample += SAMPLE_S
                    ids = ls.vehicle.getIDList()
                    speeds = np.array([ls.vehicle.getSpeed(v) for v in ids])
                    waits = np.array([ls.vehicle.getWaitingTime(v) for v in ids])
                    samples["t"].append(round(t, 1))
                    samples["vehicles"].append(len(ids))
                    samples["halted"].append(int((speeds < 0.1).sum()) if len(ids) else 0)
                    samples["waited"].append(int((waits > WAITED_S).sum()) if len(ids) else 0)
                    samples["teleports"].append(teleports)
        finally:
            ls.close()
    last = [i for i, t in enumerate(samples["t"]) if t > end - 600.0]
    jammed = [samples["halted"][i] > 0.25 * max(samples["vehicles"][i], 1) for i in last]
    summary = {
        "town": town, "level": level, "minutes": minutes, "cap": max_vehicles,
        "peak_vehicles": max(samples["vehicles"]), "final_vehicles": samples["vehicles"][-1],
        "peak_halted": max(samples["halted"]), "final_halted": samples["halted"][-1],
        "peak_waited_60s": max(samples["waited"]), "final_waited_60s": samples["waited"][-1],
        "jammed_share_last_10min": round(sum(jammed) / max(len(jammed), 1), 3),
        "teleports": teleports,
    }
    return {"summary": summary, "samples": samples}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--level", default="normal")
    ap.add_argument("--minutes", type=float, default=20.0)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--towns", default="", help="comma separated (default: every bundled town)")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--uncapped", action="store_true", help="no fleet cap (as before icrsumo had one)")
    args = ap.parse_args()
    towns = [t for t in args.towns.split(",") if t] or list(bundled_towns())
    rows = []
    print("| town | cap | peak vehicles | final vehicles | peak halted | final halted "
          "| waited > 60 s (peak / final) | last 10 min with > 25 % halted | teleports |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for town in towns:
        res = run_town(town, args.level, args.minutes, args.seed, cap=not args.uncapped)
        s = res["summary"]
        rows.append(res)
        cap = s["cap"] if s["cap"] >= 0 else "—"
        print(f"| {town} | {cap} | {s['peak_vehicles']} | {s['final_vehicles']} | {s['peak_halted']} | "
              f"{s['final_halted']} | {s['peak_waited_60s']} / {s['final_waited_60s']} | "
              f"{100 * s['jammed_share_last_10min']:.0f} % | {s['teleports']} |", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    sys.exit(main())
