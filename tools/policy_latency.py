"""Latency of one learned-agent forward pass (``icrsumo.learn.nets.Policy``) per batch size on
a device: the whole call (host arrays in, host arrays out) and, on a GPU, the padded network
pass alone. Median of ``--calls`` calls after 20 warm-up calls, in ms.

    python tools/policy_latency.py --device cuda --agents bev-token bev-ngram --batches 1 8 32
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def median_ms(fn, calls: int) -> float:
    for _ in range(20):
        fn()
    times = []
    for _ in range(calls):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3


def main(argv: list[str] | None = None) -> int:
    import torch

    from icrsumo.learn.agent import CHECKPOINTS
    from icrsumo.learn.nets import GPU_BATCH, Policy

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--agents", nargs="+", default=["bev-token"])
    ap.add_argument("--batches", nargs="+", type=int, default=[1, 8, 32])
    ap.add_argument("--calls", type=int, default=200)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    out: dict = {"device": args.device, "calls": args.calls, "agents": {}}
    for name in args.agents:
        policy = Policy(CHECKPOINTS / f"{name}.pt", device=args.device)
        row: dict = {}
        for b in args.batches:
            bev = (rng.random((b, 7, 128, 128)) < 0.1).astype(np.uint8) * 255
            texts = ["Turn left at the next intersection."] * b
            speed, stopped = np.full(b, 3.0, np.float32), np.zeros(b, np.float32)
            row[f"call_ms_b{b}"] = median_ms(lambda: policy(bev, texts, speed, stopped), args.calls)  # noqa: B023
        if policy.device.type == "cuda":
            with torch.inference_mode():
                x = torch.zeros((GPU_BATCH, 7, 128, 128), device=policy.device)
                lang = policy.language(["Turn left at the next intersection."] * GPU_BATCH)
                z = torch.zeros(GPU_BATCH, device=policy.device)

                def net(model=policy.model, x=x, lang=lang, z=z) -> None:
                    model.fuse(x, lang, z, z)
                    torch.cuda.synchronize()

                row[f"network_ms_b{GPU_BATCH}"] = median_ms(net, args.calls)
        out["agents"][name] = row
        print(name, " ".join(f"{k} {v:.3f}" for k, v in row.items()), flush=True)
    print(json.dumps(out, sort_keys=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
