"""Batched GPU inference in the real closed loop: the ICR run (real SUMO through libsumo, one
process per episode worker) of a learned agent, with its inference in four setups.

    python tools/batched_closed_loop.py --suite-dir OUT/scenarios --workers 16 --device cuda

Unlike ``tools/batched_inference.py`` (which replays recorded frames), every episode here is a
real ``icrsumo evaluate`` episode: SUMO steps, the runner renders the BEV and scores the
episode, and the agent is queried at 10 Hz. Modes (``--modes``, comma-separated):

* ``inprocess-cpu``: ``icrsumo evaluate --agent AGENT --workers N``: each worker process runs
  the network on its own core in ONNX Runtime with one thread (the default; bitwise
  repeatable);
* ``inprocess-torch``: the same with the network run by torch (one thread), the inference
  before ONNX Runtime (``benchmarks/torch_runtime.py``);
* ``inprocess-cuda``: the same with the learned agent built on ``--device`` (evaluate's
  ``agent_device`` option): every worker process holds its own CUDA context and runs batch-1
  forward passes on the shared GPU;
* ``batched``: ``icrsumo serve-agent AGENT --max-batch B`` on the GPU (127.0.0.1) and
  ``icrsumo evaluate --agent remote:URL --workers N``: the workers' concurrent ``/act``
  requests are gathered into one forward pass (``act_batch``);
* ``unbatched``: the same server with ``--max-batch 1``;
* ``ipc``: ``icrsumo evaluate --agent AGENT --batch-inference DEVICE --max-batch B``: one
  inference process on the GPU fed by the workers over a Unix socket (pickled raw arrays, no
  HTTP, no compression; :mod:`icrsumo.agents.hosting.batched`);
* ``ipc-unbatched``: the same with ``--max-batch 1``.

A mode may name its own worker count, ``MODE@N`` (e.g. ``ipc@24``: more episode workers than
cores, so that a worker's wait for the GPU is another worker's turn on a core), and an ``ipc``
mode its inference processes, ``ipc@NxP`` (``--inference-processes P``).

Each run gets a fresh out folder holding the converted suite (``--suite-dir``: the
``scenarios`` folder of an earlier ``icrsumo evaluate`` or ``convert-routes`` output, so the
machine needs libsumo but no SUMO binaries) and instructions generated once beforehand. As in
``tools/benchmark.py``, a second identical call that finds every episode stored is timed and
subtracted, so episodes/s counts episodes only. Simulated s per wall s sums the episodes'
simulated durations. Mean batch: the server's acts / batches (``GET /info``). Agreement: how
many stored episodes have the same DS, RC and termination as in-process CPU (GPU kernels
round differently from CPU ones) and as the first ``ipc`` run (whether GPU batching is
repeatable across runs and worker counts), and the mean DS of each setup.
Prints a table and one JSON line (``--json FILE`` also writes it).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / "tools"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from batched_inference import agent_info, fmt, machine, start_serve_agent, stat, stop_serve_agent  # noqa: E402

MODES = ("inprocess-cpu", "inprocess-torch", "inprocess-cuda", "batched", "unbatched", "ipc", "ipc-unbatched")


def prepare(suite_dir: Path, work: Path, families: tuple[str, ...], k: int) -> Path:
    """``work/prep`` with the converted suite and its instructions (generated once)."""
    from icrsumo.instructions.generate import GenerateOptions, generate

    prep = work / "prep"
    shutil.copytree(suite_dir, prep / "scenarios")
    generate(prep / "scenarios", prep / "instructions", GenerateOptions(families=families, k=k, seed=2026))
    return prep


def run_mode(mode: str, prep: Path, run_dir: Path, args: argparse.Namespace, log) -> tuple[dict, dict]:
    """One ICR run of ``mode``: (measurements, {episode key: (ds, rc, termination)})."""
    from icrsumo.evaluation import EvalOptions, run_evaluation
    from icrsumo.results.store import ResultStore

    shutil.copytree(prep, run_dir)
    mode, _, n = mode.partition("@")
    n, _, procs = n.partition("x")
    workers = int(n) if n else args.workers
    served = mode in ("batched", "unbatched")
    proc, spec = None, args.agent
    if mode == "inprocess-torch":
        import runpy

        spec = runpy.run_path(str(ROOT / "benchmarks" / "torch_runtime.py"))["spec_of"](args.agent)
    if served:
        cfg = {"agent": args.agent, "device": args.device}
        proc, url = start_serve_agent(cfg, args.batch if mode == "batched" else 1, log)
        spec = f"remote:{url}"
    try:
        opts = EvalOptions(out=run_dir, agents=(spec,), families=tuple(args.families), k=args.k,
                           workers=workers, quiet=True,
                           max_batch=1 if mode == "ipc-unbatched" else args.batch,
                           batch_inference=args.device if mode.startswith("ipc") else None,
                           inference_processes=int(procs) if procs else 1,
                           agent_device=args.device if mode == "inprocess-cuda" else None,
                           routes=tuple(args.routes.split(",")) if args.routes else None)
        s0 = agent_info(url)["stats"] if served else {"acts": 0, "batches": 0}
        t1 = time.perf_counter()
        result = run_evaluation(opts)
        summary = result.summary
        t2 = time.perf_counter()
        # the server's counters (HTTP), or those of evaluate's inference processes (ipc)
        s1 = agent_info(url)["stats"] if served else next(iter(result.inference.values()), None)
        run_evaluation(opts)  # all stored: reuse checks, generation, reports
        t3 = time.perf_counter()
    finally:
        if proc is not None:
            stop_serve_agent(proc)
    with ResultStore(run_dir / "results.sqlite") as store:
        recs = store.records()
    n = summary["episodes"]["done"] + summary["episodes"]["crashed"]
    episodes_s = max((t2 - t1) - (t3 - t2), 1e-9)
    res = {"workers": workers, "episodes": n, "crashed": summary["episodes"]["crashed"], "wall_s": t2 - t1,
           "episodes_s": episodes_s, "episodes_per_s": n / episodes_s,
           "sim_s_per_wall_s": sum(r.duration for r in recs) / episodes_s,
           "mean_DS": statistics.fmean(r.ds for r in recs) if recs else None}
    if s1:
        d_acts, d_batches = s1["acts"] - s0["acts"], s1["batches"] - s0["batches"]
        res["processes"] = s1.get("processes", 1)
        res["acts"] = d_acts
        res["mean_batch"] = d_acts / d_batches if d_batches else None
        res["largest_batch"] = s1["largest_batch"]
        for key in ("run_s", "io_s", "wait_s"):  # the inference process's time split (ipc)
            if key in s1:
                res[f"server_{key}"] = s1[key]
    episodes = {(r.route_id, r.family, r.k, r.seed): (r.ds, r.rc, r.termination) for r in recs}
    return res, episodes


def print_table(header: list[str], rows: list[list]) -> None:
    """A Markdown table after a blank line; columns after the first right-aligned."""
    print()
    print("| " + " | ".join(header) + " |")
    print("|---|" + "---:|" * (len(header) - 1))
    for row in rows:
        print("| " + " | ".join(str(c) for c in row) + " |")


def main(argv: list[str] | None = None) -> int:
    from icrsumo.instructions.families import FAMILIES

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--suite-dir", type=Path, required=True,
                    help="a converted suite (the scenarios folder of an icrsumo evaluate out folder)")
    ap.add_argument("--agent", default="bev-token")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--batch", type=int, default=16, help="serve-agent --max-batch of the batched mode")
    ap.add_argument("--device", default="cuda", help="inference device of the GPU modes")
    ap.add_argument("--modes", default=",".join(MODES))
    ap.add_argument("--families", nargs="+", default=list(FAMILIES))
    ap.add_argument("--k", type=int, default=8)
    ap.add_argument("--routes", help="comma-separated route ids (default: all)")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--work", type=Path, help="working folder (default: a temporary one)")
    ap.add_argument("--json", type=Path, help="also write the JSON line here")
    args = ap.parse_args(argv)
    modes = [m for m in args.modes.split(",") if m]
    bad = [m for m in modes if m.partition("@")[0] not in MODES
           or "@" in m and not m.partition("@")[2].replace("x", "", 1).isdigit()]
    if bad:
        ap.error(f"unknown mode {bad[0]}: use {', '.join(MODES)}")
    work = args.work or Path(tempfile.mkdtemp(prefix="icrsumo-bcl-"))
    work.mkdir(parents=True, exist_ok=True)
    log = open(work / "servers.log", "ab")  # noqa: SIM115 (closed at the end)

    def say(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    prep = prepare(args.suite_dir, work, tuple(args.families), args.k)
    runs: dict[str, list[dict]] = {m: [] for m in modes}
    episodes: dict[str, dict] = {}
    for rep in range(args.repeats):
        for mode in modes:  # interleaved per repeat
            res, eps = run_mode(mode, prep, work / f"{mode}_{rep}", args, log)
            runs[mode].append(res)
            episodes.setdefault(mode, eps)
            say(f"  {mode} repeat {rep + 1}/{args.repeats}: {res['episodes']} episodes in "
                f"{res['wall_s']:.1f} s, {res['episodes_per_s']:.2f} episodes/s"
                + (f", mean batch {res['mean_batch']:.2f}" if res.get("mean_batch") else ""))
            shutil.rmtree(work / f"{mode}_{rep}", ignore_errors=True)
    log.close()

    ref = episodes.get("inprocess-cpu")
    ipc = next((episodes[m] for m in modes if m.partition("@")[0] == "ipc"), None)
    out: dict = {"machine": machine(), "agent": args.agent, "workers": args.workers, "batch": args.batch,
                 "families": args.families, "k": args.k, "repeats": args.repeats, "modes": {}}
    for mode in modes:
        rs = runs[mode]
        row = {key: stat([r.get(key) for r in rs]) for key in
               ("wall_s", "episodes_per_s", "sim_s_per_wall_s", "mean_batch", "mean_DS")}
        for key in ("server_run_s", "server_io_s", "server_wait_s"):
            if key in rs[0]:
                row[key] = stat([r.get(key) for r in rs])
        row["episodes"] = rs[0]["episodes"]
        row["crashed"] = rs[0]["crashed"]
        row["workers"] = rs[0]["workers"]
        for label, other in (("same_as_cpu", ref), ("same_as_ipc", ipc)):
            if other is not None:
                row[label] = sum(episodes[mode].get(key) == v for key, v in other.items())
        out["modes"][mode] = row
    base = {m: out["modes"][m]["episodes_per_s"]["median"] for m in modes}
    for mode in modes:
        for other in ("unbatched", "inprocess-cpu"):
            if other in base and base[other]:
                out["modes"][mode][f"x_{other}"] = base[mode] / base[other]

    m = out["machine"]
    print(f"machine: {m.get('gpu', 'no GPU')}, {m['cpus']} CPUs, Python {m['python']}, torch "
          f"{m.get('torch')}; agent {args.agent}, {args.workers} episode workers, families "
          f"{','.join(args.families)}, K = {args.k}, {args.repeats} repeat(s)")

    def ratio(r: dict, key: str) -> str:
        return f"{r[key]:.2f}" if key in r else "—"

    def same(r: dict, key: str) -> str:
        return f"{r[key]}/{r['episodes']}" if key in r else "—"

    rows = [[mode, r["workers"], r["episodes"], fmt(r["wall_s"], 1), fmt(r["episodes_per_s"], 2),
             fmt(r["sim_s_per_wall_s"], 0), fmt(r["mean_batch"], 2), ratio(r, "x_unbatched"),
             ratio(r, "x_inprocess-cpu"), fmt(r["mean_DS"], 1, rng=False), same(r, "same_as_cpu"),
             same(r, "same_as_ipc")] for mode, r in out["modes"].items()]
    print_table(["setup", "workers", "episodes", "wall s", "episodes/s", "sim s per wall s", "mean batch",
                 "× unbatched", "× in-process CPU", "mean DS", "same as CPU", "same as ipc"], rows)
    split = [[mode, r["workers"], fmt(r["server_run_s"], 1), fmt(r["server_io_s"], 1),
              fmt(r["server_wait_s"], 1)] for mode, r in out["modes"].items() if "server_run_s" in r]
    if split:
        print_table(["inference processes (ipc, summed)", "workers", "running the agent s",
                     "reading + answering s", "waiting for requests s"], split)
    line = json.dumps(out, sort_keys=True)
    print()
    print(line)
    if args.json:
        args.json.write_text(line + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
