"""Batched agent inference across parallel episodes: act throughput and episodes/s of a learned
agent served by ``icrsumo serve-agent`` with and without batching, and in-process on CPU.

SUMO is *replayed*: every "episode worker" process sends recorded BEV frames (``--replay DIR``
of ``icrsumo.learn.collect`` episode ``.npz`` files, bit-packed ``bev``, ``speed`` and
``instruction`` indices into the JSON ``instructions``; without it synthetic frames of a drawn
road) in order, and busy-waits ``--sim-ms`` per act to emulate the simulator and runner time
of a closed loop (default 1.5 ms: 2 simulation steps of 0.74 ms, the "runner only" row of the
README's Performance table). So the numbers need no SUMO (the GPU machine has none) and
reflect a closed loop whose simulator side costs a fixed time per act.

Modes (``--modes``, comma-separated):

* ``batched``: ``icrsumo serve-agent AGENT --max-batch B --device DEVICE`` on 127.0.0.1; N
  client processes, each its own session (``RemoteAgent``);
  the server gathers concurrent ``/act`` requests into batches (the agent's ``act_batch``);
* ``unbatched``: the same with ``--max-batch 1``;
* ``inprocess-cpu``: no server; N processes each running ``LearnedAgent.act`` on CPU with one
  torch thread (how ``icrsumo evaluate --workers N`` runs a learned agent);
* ``inprocess-cuda``: the same on ``--device`` (each process its own CUDA context).

Every mode: N workers warm up (``--warmup`` acts each), start together and act as fast as
answers come for ``--seconds``; acts/s = acts completed in that window / its length. Mean
batch = the server's acts / batches over the window (``GET /info`` stats). Episodes/s = acts/s
/ ``--acts-per-episode`` (default 160: the tiny suite's mean episode is 16.0 s of simulated
time at 10 Hz, route-oracle's full ICR run of 528 episodes; ``--results-db`` computes it from a
``results.sqlite``); it leaves out SUMO start and the 20 s traffic warm-up of each episode.
Each number is the median of ``--repeats`` [min-max], modes interleaved per repeat. Prints a
table and one JSON line (``--json FILE`` also writes it).
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import os
import platform
import sqlite3
import statistics
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

MODES = ("batched", "unbatched", "inprocess-cpu", "inprocess-cuda")
TEXTS = ("Start the route and keep following the road.", "After 40 meters, turn right at the intersection.",
         "Go straight through the next junction.", "Turn left at the next intersection.")


# --------------------------------------------------------------------------- frames
def synthetic_episode(idx: int, n: int = 64) -> dict:
    """``n`` frames of a drawn road (drivable band, dashed centre line moving down, ego box, a
    vehicle ahead coming closer, a right branch appearing), speeds and instruction texts."""
    bev = np.zeros((n, 7, 128, 128), np.uint8)
    rng = np.random.default_rng(idx)
    lead = int(rng.integers(0, 40))
    for i in range(n):
        f = bev[i]
        f[0, :, 44:84] = 255                                   # drivable
        if i >= n // 2:
            f[0, 30:60, 84:] = 255                             # a branch to the right
        for r in range(-16, 128, 16):                          # dashed centre line, moving
            r0 = r + (2 * i) % 16
            f[1, max(r0, 0):max(r0 + 8, 0), 63:65] = 255
        f[4, 100:112, 58:70] = 255                             # ego (heading up)
        row = (lead + 2 * i) % 90
        f[2, row:row + 10, 52:62] = 255                        # a vehicle ahead
    speed = (5.0 + 2.0 * np.sin(np.arange(n) / 10.0 + idx)).astype(np.float32)
    texts = [TEXTS[(idx + i // 16) % len(TEXTS)] for i in range(n)]
    return {"bev": bev, "speed": speed, "texts": texts}


def replay_files(replay: Path | None) -> list[Path]:
    if replay is None:
        return []
    files = sorted(Path(replay).glob("*.npz"))
    if not files:
        raise SystemExit(f"{replay}: no recorded episodes (*.npz)")
    return files


def load_episode(files: list[str], idx: int, max_frames: int) -> dict:
    """Worker ``idx``'s episode: recorded file ``idx % len(files)`` (started at another frame
    when several workers share a file) or, without files, a synthetic one."""
    if not files:
        return synthetic_episode(idx)
    with np.load(files[idx % len(files)]) as d:
        n = len(d["bev"])
        start = ((idx // len(files)) * 37) % n
        sel = (np.arange(min(n, max_frames)) + start) % n
        bev = np.unpackbits(d["bev"][sel], axis=-1) * np.uint8(255)
        instructions = json.loads(str(d["instructions"]))
        texts = [instructions[int(k)]["text"] if k >= 0 else "" for k in d["instruction"][sel]]
        return {"bev": np.ascontiguousarray(bev), "speed": d["speed"][sel].astype(np.float32), "texts": texts}


def observations(ep: dict):
    """Observations of ``ep``'s frames in order, over and over, at 10 Hz."""
    from icrsumo.agents.base import Observation

    texts = ep["texts"]
    ids = {t: i for i, t in enumerate(dict.fromkeys(texts))}
    k = 0
    while True:
        i = k % len(texts)
        yield Observation(t=0.1 * k, bev=ep["bev"][i], speed=float(ep["speed"][i]), instruction=texts[i],
                          instruction_id=ids[texts[i]], notice="")
        k += 1


def busy_wait(ms: float) -> None:
    """Spin ``ms`` milliseconds (the simulator's CPU time; sleeping would free the core)."""
    if ms > 0:
        end = time.perf_counter() + ms / 1000.0
        while time.perf_counter() < end:
            pass


# --------------------------------------------------------------------------- workers
def _worker(idx: int, cfg: dict, ready, go, start, out) -> None:
    """One replayed episode: reset an agent (remote or in-process), warm up, then act in a
    closed loop with ``sim_ms`` of simulated work per act until the common deadline."""
    try:
        from icrsumo.agents.base import EpisodeInfo

        info = EpisodeInfo(route_id=f"replay_{idx}", town="replay", net="", step_length=0.05,
                           control_dt=0.1, seed=idx)
        if cfg["url"]:
            from icrsumo.agents.remote import RemoteAgent

            agent = RemoteAgent(cfg["url"], "bench", timeout=300.0)
        else:
            from icrsumo.agents.registry import agent_factory

            agent = agent_factory(cfg["agent"], cfg["device"])()
        agent.reset(info)
        obs = observations(load_episode(cfg["files"], idx, cfg["max_frames"]))
        for _ in range(cfg["warmup"]):
            agent.act(next(obs))
            busy_wait(cfg["sim_ms"])
        ready.wait()
        go.wait()
        t0 = start.value
        deadline = t0 + cfg["seconds"]
        while time.monotonic() < t0:
            pass
        acts, lat = 0, []
        while True:
            o = next(obs)
            a = time.monotonic()
            if a >= deadline:
                break
            agent.act(o)
            b = time.monotonic()
            if b <= deadline:
                acts += 1
                lat.append(b - a)
            busy_wait(cfg["sim_ms"])
        if hasattr(agent, "close"):
            agent.close()
        out.put({"idx": idx, "acts": acts, "lat_ms": 1000.0 * float(np.median(lat)) if lat else None,
                 "lat_p95_ms": 1000.0 * float(np.percentile(lat, 95)) if lat else None})
    except BaseException as err:  # noqa: BLE001 - reported by the main process
        out.put({"idx": idx, "error": f"{type(err).__name__}: {err}"})
        ready.abort()  # the main process stops waiting at once
        go.abort()
        raise


def agent_info(url: str) -> dict:
    """The ``/info`` answer of the serve-agent process at ``url`` (30 s time limit)."""
    with urllib.request.urlopen(url + "/info", timeout=30) as r:
        return json.loads(r.read())


def start_serve_agent(cfg: dict, max_batch: int, log) -> tuple[subprocess.Popen, str]:
    """Start ``icrsumo serve-agent`` for ``cfg["agent"]`` on ``cfg["device"]`` with batches of up
    to ``max_batch``, its output to ``log``; return the process and its URL once it answers
    (RuntimeError if it exits or does not answer within 120 s)."""
    from icrsumo.agents.remote import free_port

    port = free_port()
    env = dict(os.environ,
               PYTHONPATH=os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p))
    cmd = [sys.executable, "-m", "icrsumo", "serve-agent", cfg["agent"], "--port", str(port),
           "--max-batch", str(max_batch), "--device", cfg["device"]]
    proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=log)
    url = f"http://127.0.0.1:{port}"
    t_end = time.monotonic() + 120
    while True:
        if proc.poll() is not None:
            raise RuntimeError(f"serve-agent exited with status {proc.returncode}")
        try:
            agent_info(url)
            return proc, url
        except OSError:
            if time.monotonic() > t_end:
                proc.kill()
                raise RuntimeError("serve-agent did not answer within 120 s") from None
            time.sleep(0.1)


def stop_serve_agent(proc: subprocess.Popen) -> None:
    """Stop a serve-agent process (SIGTERM, then SIGKILL after 30 s)."""
    proc.terminate()
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()


def run_mode(mode: str, args: argparse.Namespace, files: list[str], log) -> dict:
    """One measurement of ``mode``: {acts_per_s, mean_batch, lat_ms, ...}."""
    served = mode in ("batched", "unbatched")
    device = "cpu" if mode == "inprocess-cpu" else args.device
    max_batch = args.batch if mode == "batched" else 1
    cfg = {"agent": args.agent, "device": device, "files": files, "max_frames": args.max_frames,
           "warmup": args.warmup, "sim_ms": args.sim_ms, "seconds": args.seconds, "url": None}
    proc = None
    if served:
        proc, cfg["url"] = start_serve_agent(cfg, max_batch, log)
    ctx = mp.get_context("spawn")
    n = args.clients
    ready, go = ctx.Barrier(n + 1), ctx.Barrier(n + 1)
    start, out = ctx.Value("d", 0.0), ctx.Queue()
    workers = [ctx.Process(target=_worker, args=(i, cfg, ready, go, start, out), daemon=True)
               for i in range(n)]
    try:
        for w in workers:
            w.start()
        try:
            ready.wait(timeout=600)
        except threading.BrokenBarrierError:
            errors = [r["error"] for r in _drain(out) if "error" in r]
            raise RuntimeError(f"{mode}: workers failed: {errors[:2] or 'timeout'}") from None
        start.value = time.monotonic() + 0.05
        s0 = agent_info(cfg["url"])["stats"] if served else None
        go.wait(timeout=60)
        time.sleep(max(0.0, start.value + args.seconds - time.monotonic()))
        s1 = agent_info(cfg["url"])["stats"] if served else None
        results = [out.get(timeout=300) for _ in range(n)]
        for w in workers:
            w.join(timeout=60)
    finally:
        for w in workers:
            if w.is_alive():
                w.kill()
        if proc is not None:
            stop_serve_agent(proc)
    errors = [r["error"] for r in results if "error" in r]
    if errors:
        raise RuntimeError(f"{mode}: {errors[0]}")
    acts = sum(r["acts"] for r in results)
    res = {"acts": acts, "acts_per_s": acts / args.seconds}
    for key in ("lat_ms", "lat_p95_ms"):  # median over the workers
        res[key] = float(np.median([r[key] for r in results if r[key] is not None] or [math.nan]))
    if served:
        d_acts, d_batches = s1["acts"] - s0["acts"], s1["batches"] - s0["batches"]
        res["mean_batch"] = d_acts / d_batches if d_batches else None
        res["largest_batch"] = s1["largest_batch"]
    return res


def _drain(q) -> list[dict]:
    items = []
    while True:
        try:
            items.append(q.get(timeout=0.5))
        except Exception:
            return items


# --------------------------------------------------------------------------- summary
def acts_per_episode_from(db: Path, control_dt: float = 0.1) -> tuple[float, int]:
    """Mean agent acts per stored episode (duration / control_dt + 1) and the episode count."""
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        rows = [r[0] for r in con.execute("SELECT duration FROM episodes WHERE status = 'done' "
                                          "AND duration IS NOT NULL")]
    finally:
        con.close()
    if not rows:
        raise SystemExit(f"{db}: no finished episodes")
    return statistics.fmean(rows) / control_dt + 1.0, len(rows)


def stat(values: list[float]) -> dict:
    vals = [v for v in values if v is not None and not math.isnan(v)]
    if not vals:
        return {"median": None, "min": None, "max": None}
    return {"median": statistics.median(vals), "min": min(vals), "max": max(vals)}


def fmt(s: dict, nd: int = 0, rng: bool = True) -> str:
    if s["median"] is None:
        return "—"
    m = f"{s['median']:.{nd}f}"
    if rng and len({s["min"], s["max"]}) > 1:
        return f"{m} [{s['min']:.{nd}f}–{s['max']:.{nd}f}]"
    return m


def machine() -> dict:
    info = {"python": platform.python_version(), "cpus": os.cpu_count(), "platform": platform.machine()}
    try:
        import torch

        info["torch"] = torch.__version__
        if torch.cuda.is_available():
            info["gpu"] = torch.cuda.get_device_name(0)
    except ImportError:
        pass
    return info


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--agent", default="bev-token", help="learned agent spec (default bev-token)")
    ap.add_argument("--modes", default="batched,unbatched,inprocess-cpu",
                    help=f"comma-separated, of {', '.join(MODES)} (default: the first three)")
    ap.add_argument("--clients", type=int, default=2, help="parallel episode workers N (default 2)")
    ap.add_argument("--batch", type=int, default=16, help="--max-batch of the batched mode (default 16)")
    ap.add_argument("--device", default="auto",
                    help="device of the served / inprocess-cuda agent: cpu, cuda, auto (default auto)")
    ap.add_argument("--sim-ms", type=float, default=1.5,
                    help="busy-wait per act emulating SUMO + runner (default 1.5 ms = 2 steps x 0.74 ms)")
    ap.add_argument("--seconds", type=float, default=2.0, help="measured window per mode (default 2 s)")
    ap.add_argument("--warmup", type=int, default=5, help="acts per worker before the window (default 5)")
    ap.add_argument("--repeats", type=int, default=1, help="repeats; medians reported (default 1)")
    ap.add_argument("--replay", type=Path, default=None,
                    help="folder of recorded episodes (*.npz); default: synthetic frames of a drawn road")
    ap.add_argument("--max-frames", type=int, default=300,
                    help="frames per replayed episode at most (default 300)")
    ap.add_argument("--acts-per-episode", type=float, default=160.0,
                    help="mean agent acts per tiny-suite episode (default 160: 16.0 s at 10 Hz)")
    ap.add_argument("--results-db", type=Path, default=None,
                    help="results.sqlite of an ICR run: mean acts per episode taken from it")
    ap.add_argument("--json", type=Path, default=None, help="also write the JSON line to this file")
    ap.add_argument("--server-log", type=Path, default=None, help="serve-agent output (default: discarded)")
    args = ap.parse_args(argv)
    modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    bad = [m for m in modes if m not in MODES]
    if bad or not modes:
        ap.error(f"unknown mode(s) {', '.join(bad)}; use {', '.join(MODES)}")
    if args.clients < 1 or args.batch < 1 or args.repeats < 1 or args.seconds <= 0:
        ap.error("--clients, --batch and --repeats must be at least 1, --seconds positive")
    ape, ape_src = args.acts_per_episode, "--acts-per-episode"
    if args.results_db is not None:
        ape, n_eps = acts_per_episode_from(args.results_db)
        ape_src = f"{args.results_db} ({n_eps} episodes)"
    files = [str(f) for f in replay_files(args.replay)]
    os.environ.setdefault("OMP_NUM_THREADS", "1")  # inherited by the spawned workers

    runs: dict[str, list[dict]] = {m: [] for m in modes}
    failed: dict[str, str] = {}
    log = open(args.server_log, "ab") if args.server_log else subprocess.DEVNULL  # noqa: SIM115
    try:
        for rep in range(args.repeats):
            for m in modes:
                if m in failed:
                    continue
                try:
                    r = run_mode(m, args, files, log)
                except Exception as err:  # noqa: BLE001 - the other modes still run; reported below
                    failed[m] = f"{type(err).__name__}: {err}"
                    print(f"# {m} failed: {failed[m]}", file=sys.stderr, flush=True)
                    continue
                runs[m].append(r)
                print(f"# repeat {rep + 1}/{args.repeats} {m}: {r['acts_per_s']:.0f} acts/s"
                      + (f", mean batch {r['mean_batch']:.2f}" if r.get("mean_batch") else ""),
                      file=sys.stderr, flush=True)
    finally:
        if log is not subprocess.DEVNULL:
            log.close()

    summary = {}
    for m, rs in runs.items():
        if m in failed:
            continue
        aps = [r["acts_per_s"] for r in rs]
        summary[m] = {
            "clients": args.clients,
            "max_batch": args.batch if m == "batched" else (1 if m == "unbatched" else None),
            "device": "cpu" if m == "inprocess-cpu" else args.device,
            "acts_per_s": stat(aps), "episodes_per_s": stat([a / ape for a in aps]),
            "sim_s_per_wall_s": stat([a * 0.1 for a in aps]),
            "act_round_trip_ms": stat([r["lat_ms"] for r in rs]),
            "act_round_trip_p95_ms": stat([r["lat_p95_ms"] for r in rs]),
            "mean_batch": stat([r.get("mean_batch") for r in rs]),
            "repeats": [r["acts_per_s"] for r in rs],
        }
    base = "inprocess-cpu" if "inprocess-cpu" in summary else None
    for s in summary.values():
        s["speedup_vs_inprocess_cpu"] = (s["acts_per_s"]["median"] / summary[base]["acts_per_s"]["median"]
                                         if base else None)
        s["speedup_vs_unbatched"] = (s["acts_per_s"]["median"] / summary["unbatched"]["acts_per_s"]["median"]
                                     if "unbatched" in summary else None)
    res = {"agent": args.agent, "clients": args.clients, "sim_ms": args.sim_ms, "seconds": args.seconds,
           "repeats": args.repeats, "frames": f"replay {args.replay} ({len(files)} episodes)" if files
           else "synthetic", "acts_per_episode": ape, "acts_per_episode_source": ape_src,
           "machine": machine(), "modes": summary, "failed": failed}

    print(f"\nagent {args.agent}, N = {args.clients} episode workers, {args.sim_ms:g} ms simulated CPU "
          f"per act, "
          f"{args.seconds:g} s windows, {args.repeats} repeat(s), frames: {res['frames']}, "
          f"{ape:.0f} acts per episode ({ape_src})\n")
    print("| mode | device | max batch | acts/s | mean batch | act round trip ms (median / p95) "
          "| episodes/s | sim s per wall s | × unbatched | × in-process CPU |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for m, s in summary.items():
        x_unb = f"{s['speedup_vs_unbatched']:.2f}" if s["speedup_vs_unbatched"] else "—"
        x_cpu = f"{s['speedup_vs_inprocess_cpu']:.2f}" if s["speedup_vs_inprocess_cpu"] else "—"
        print(f"| {m} | {s['device']} | {s['max_batch'] or '—'} | {fmt(s['acts_per_s'])} "
              f"| {fmt(s['mean_batch'], 2)} | {fmt(s['act_round_trip_ms'], 2, False)} / "
              f"{fmt(s['act_round_trip_p95_ms'], 2, False)} | {fmt(s['episodes_per_s'], 1)} "
              f"| {fmt(s['sim_s_per_wall_s'], 0)} | {x_unb} | {x_cpu} |")
    for m, why in failed.items():
        print(f"| {m} | failed: {why} |")
    line = json.dumps(res, sort_keys=True)
    if args.json:
        args.json.write_text(line + "\n")
    print(line)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
