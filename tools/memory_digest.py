"""The learned agents' instruction memory on this CPU: one digest over many synthetic drives.

    python tools/memory_digest.py [--episodes 400] [--steps 1500] [--seed 2026]

Drives :class:`icrsumo.learn.memory.InstructionMemory` through ``--episodes`` synthetic episodes
of ``--steps`` decisions each (0.1 s apart), drawn from a seeded ``numpy.random.Generator``:
instructions from the bundled baseline bank (``[x]`` filled with a drawn distance) changing at
random, the heading a random walk with turns of 30-180 degrees either way and lane-change
swerves, the speed 0-20 m/s with stops. The digest is the SHA-256 of every step's chosen text and
the exact bits of the memory's odometer and sideways distance (IEEE sums, Python's ``math.sin``,
the compass wrap): the same digest on two CPUs means the memory decides the same there
(docs/exact.md). Prints the digest, the steps driven, how many of them the memory replaced the
text in, and the CPU's name.
"""

from __future__ import annotations

import argparse
import hashlib
import math
import struct
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from cpu import cpu_name  # noqa: E402

from icrsumo.agents.base import Observation  # noqa: E402
from icrsumo.core.angles import wrap_angle  # noqa: E402
from icrsumo.instructions.banks import load_banks  # noqa: E402
from icrsumo.learn.memory import InstructionMemory  # noqa: E402

DT = 0.1
BEV = np.zeros((7, 8, 8), np.uint8)


def texts() -> list[str]:
    """Every baseline phrasing of the bundled bank, in a fixed order."""
    bank = load_banks().baseline
    return [t for key in sorted(bank) for t in bank[key]]


def drive(mem: InstructionMemory, rng: np.random.Generator, pool: list[str], steps: int, h) -> int:
    """One synthetic episode into hash ``h``; returns the steps whose text the memory replaced."""
    replaced = 0
    heading, speed, iid, text, turn_left = float(rng.uniform(-math.pi, math.pi)), 8.0, -1, "", 0.0
    for _ in range(steps):
        if iid < 0 or rng.random() < 0.01:                       # a new instruction
            iid += 1
            text = pool[int(rng.integers(len(pool)))].replace("[x]", str(int(rng.integers(20, 300))))
        if turn_left == 0.0 and rng.random() < 0.02:            # a turn or a swerve begins
            turn_left = math.radians(float(rng.choice([-180, -90, -30, -8, 8, 30, 90, 180])))
        if turn_left != 0.0:
            d = math.copysign(min(abs(turn_left), math.radians(4.0)), turn_left)
            heading, turn_left = heading + d, turn_left - d
        heading = wrap_angle(heading + float(rng.normal(0.0, 0.002)))
        speed = 0.0 if rng.random() < 0.002 else min(max(speed + float(rng.normal(0.0, 0.3)), 0.0), 20.0)
        obs = Observation(t=0.0, bev=BEV, speed=speed, instruction=text, instruction_id=iid, notice="",
                          compass=heading)
        chosen = mem.text(obs, DT)
        replaced += chosen != text
        h.update(chosen.encode("utf-8") + struct.pack("<dd", mem.odometer, mem.lateral))
    return replaced


def digest(episodes: int, steps: int, seed: int) -> tuple[str, int]:
    """The digest and the number of steps whose text the memory replaced."""
    rng, pool, h = np.random.default_rng(seed), texts(), hashlib.sha256()
    replaced = sum(drive(InstructionMemory(), rng, pool, steps, h) for _ in range(episodes))
    return "sha256:" + h.hexdigest(), replaced


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=400)
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--seed", type=int, default=2026)
    a = ap.parse_args(argv)
    d, replaced = digest(a.episodes, a.steps, a.seed)
    print(f"{d} ({a.episodes * a.steps:,} steps, {replaced:,} read as the memory chose, {cpu_name()})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
