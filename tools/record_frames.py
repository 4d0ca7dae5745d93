"""Record the simulator frames of real episodes as golden files for the SUMO-free sensor tests.

For each case below: convert the bundled route (no background traffic unless stated), drive it
with the named agent and write ``tests/data/frames/<case>.json``: the scenario's network
name, route polyline and edges, the ego's size, and per recorded step the frame
(:func:`icrsumo.sim.frame.frame_to_dict`), the ego's state (x, y, yaw, speed) and the step's
logged readings and events. ``tests/sim/test_sensors.py`` replays the pure sensors over the
frames and must find the logged events and columns again, float for float.

    python tools/record_frames.py
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from icrsumo.agents.base import Action  # noqa: E402
from icrsumo.agents.privileged import RouteOracle  # noqa: E402
from icrsumo.core.resources import bundled_suites  # noqa: E402
from icrsumo.instructions.banks import load_banks  # noqa: E402
from icrsumo.instructions.generate import baseline_set  # noqa: E402
from icrsumo.sim.callbacks import EpisodeCallback  # noqa: E402
from icrsumo.sim.episode import run_episode  # noqa: E402
from icrsumo.sim.frame import frame_to_dict  # noqa: E402
from icrsumo.world.convert import ConvertOptions, convert_routes  # noqa: E402
from icrsumo.world.dynamics import Control  # noqa: E402
from icrsumo.world.scenario import find_scenarios, read_scenario  # noqa: E402

OUT = ROOT / "tests" / "data" / "frames"


class Swerve:
    """Full left lock at low throttle: leaves the road (roadside) and turns against lanes."""

    name, privileged = "swerve", False

    def reset(self, info) -> None:
        pass

    def act(self, obs) -> Action:
        return Action(control=Control(steer=1.0, throttle=0.4))


class Blind(RouteOracle):
    """The route-oracle ignoring lights, stop signs and vehicles at a fixed 8 m/s."""

    name = "blind-oracle"

    def _target_speed(self, w, path, t):
        return 8.0


class FrameTape(EpisodeCallback):
    """Keeps every recorded step's frame and ego state."""

    def __init__(self) -> None:
        self.rows: list[dict] = []

    def on_step(self, episode, step) -> None:
        st = episode.state
        self.rows.append({"frame": frame_to_dict(episode.frame),
                          "ego": [st.x, st.y, st.yaw, st.speed],
                          "step": [step.progress, step.route_dist, step.outside, step.instruction],
                          "events": [[str(e.kind), e.t, e.pos, e.other, e.x, e.y] for e in step.events]})


#: case -> (split, route, traffic, agent factory)
CASES = {
    "swerve_tiny_003": ("tiny", "tiny_003", "none", Swerve),        # roadside, wrong way
    "blind_tiny_000": ("tiny", "tiny_000", "normal", Blind),        # red light
    "blind_tiny_001": ("tiny", "tiny_001", "normal", Blind),        # vehicle collision
    "blind_tiny_012": ("tiny", "tiny_012", "normal", Blind),        # stop sign
}
#: steps kept per case (a prefix: the sensors' state runs from the first step)
MAX_STEPS = 500


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        for case, (split, rid, traffic, make) in CASES.items():
            out = Path(tmp) / f"{split}-{traffic}"
            if not out.is_dir():
                rep = convert_routes(bundled_suites()[split], out, ConvertOptions(traffic=traffic, workers=2))
                assert not rep.failures, rep.failures
            sc = next(read_scenario(d) for d in find_scenarios(out) if read_scenario(d).route_id == rid)
            iset, _ = baseline_set(sc, load_banks(None), 0)
            tape = FrameTape()
            log = run_episode(sc, iset, make(), callbacks=[tape])
            doc = {"case": case, "town": sc.town, "net": Path(sc.net).name, "route_id": rid,
                   "polyline": [list(p) for p in sc.polyline], "edges": list(sc.ego_edges),
                   "size": [sc.ego.length, sc.ego.width],
                   "termination": str(log.termination), "steps": tape.rows[:MAX_STEPS]}
            path = OUT / f"{case}.json"
            path.write_text(json.dumps(doc, separators=(",", ":")) + "\n", encoding="utf-8")
            kinds = sorted({e[0] for r in doc["steps"] for e in r["events"]})
            print(f"{path.relative_to(ROOT)}: {len(doc['steps'])} steps, {log.termination}, events {kinds}")


if __name__ == "__main__":
    main()
