"""Generate the bundled CARLA towns (networks/carla/TownXX.net.xml) from the source networks.

Usage: python tools/make_carla_networks.py [--src ../shared/carla] [--out networks/carla]

The sources are CARLA's eight LangAuto towns (Town01 ... Town07, Town10HD) as SUMO networks,
converted from CARLA's OpenDRIVE maps by netconvert 1.20 (see ``--src``'s README: published
by the Scenic project, MIT licence notice of the CARLA project). They carry driving lanes
only. This script runs SUMO's netconvert on each with the fixed options in :data:`OPTIONS`:
sidewalks guessed along urban streets (speed limit 5.8-13.89 m/s, netconvert's defaults) and
pedestrian crossings and walking areas guessed at their junctions, so that pedestrians walk
and cross as in icrsumo's own towns; everything else (geometry, lanes, connections, traffic
lights, the netOffset that maps CARLA coordinates to SUMO's) is kept, except roundabouts that
are none: a ``<roundabout>`` whose ring nodes lie more than :data:`ROUNDABOUT_MAX_RADIUS_M`
from their centroid (Town06's highway loop, 73-90 m, guessed by the source's conversion) is
dropped, so that no instruction calls it a roundabout; Town03's roundabout (18-29 m) stays.
The leading
``<!-- generated on ... -->`` comment (date, paths) is stripped, so the output is
byte-identical on every run (tested). The licence notice and a README with the credit are
copied next to the networks.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from icrsumo.core.fsio import strip_header_comments, write_atomic  # noqa: E402
from icrsumo.core.resources import sumo_binary, sumo_home  # noqa: E402

TOWNS = ("Town01", "Town02", "Town03", "Town04", "Town05", "Town06", "Town07", "Town10HD")
#: netconvert options applied to every source network
OPTIONS = [
    "--sidewalks.guess", "true",
    "--crossings.guess", "true",
    "--walkingareas", "true",
    "--no-turnarounds.except-deadend", "true",
    "--offset.disable-normalization", "true",
    "--output.street-names", "false",
    "--xml-validation", "never",
]
#: ring nodes farther than this (m) from their centroid: not a roundabout
ROUNDABOUT_MAX_RADIUS_M = 50.0
NOTICE = "LICENSE-CARLA.txt"
README = """# CARLA's LangAuto towns (bundled)

`Town01` ... `Town07` and `Town10HD`, the eight CARLA towns that LangAuto's routes use, as SUMO
networks. Source: CARLA's OpenDRIVE maps converted to SUMO by netconvert 1.20.0 (as published
in the Scenic project's repository, `assets/maps/CARLA/`), from the CARLA project
(https://carla.org, (c) Computer Vision Center, Universitat Autonoma de Barcelona); see
`LICENSE-CARLA.txt` for the licence notice that came with them. CARLA's assets are
distributed under CC-BY: credit the CARLA project when you use or redistribute them.

icrsumo changed them only by running netconvert once more (`tools/make_carla_networks.py`):
guessed sidewalks, pedestrian crossings and walking areas were added, and Town06's highway
loop (ring radius 73-90 m), which the source marked as a roundabout, is no longer marked as
one; lanes, geometry, connections, traffic lights and the CARLA coordinate offset are
unchanged.
"""


def drop_false_roundabouts(text: str, net_path: Path) -> str:
    """``text`` (the network file at ``net_path``) without the ``<roundabout>`` elements whose
    ring nodes lie more than ROUNDABOUT_MAX_RADIUS_M (m) from their centroid."""
    import numpy as np
    import sumolib

    net = sumolib.net.readNet(str(net_path))
    for r in net.getRoundabouts():
        xy = np.array([net.getNode(n).getCoord()[:2] for n in r.getNodes()], dtype=float)
        if np.hypot(*(xy - xy.mean(axis=0)).T).max() > ROUNDABOUT_MAX_RADIUS_M:
            ring = f'edges="{" ".join(r.getEdges())}"'
            lines = text.splitlines(keepends=True)
            hits = [i for i, ln in enumerate(lines)
                    if ln.lstrip().startswith("<roundabout ") and ring in ln]
            if len(hits) != 1:
                raise SystemExit(f"{net_path}: roundabout {ring} found {len(hits)} times, expected once")
            del lines[hits[0]]
            text = "".join(lines)
    return text


def convert(src: Path, dst: Path) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / dst.name
        env = dict(os.environ, PROJ_LIB=str(sumo_home() / "data" / "proj"))
        res = subprocess.run([sumo_binary("netconvert"), "-s", str(src), *OPTIONS, "-o", str(out)],
                             capture_output=True, text=True, env=env)
        if res.returncode != 0:
            raise SystemExit(f"netconvert failed on {src}: {res.stderr.strip()[-2000:]}")
        text = strip_header_comments(out.read_text(encoding="utf-8"))
        write_atomic(dst, drop_false_roundabouts(text, out))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--src", type=Path, default=ROOT.parent / "shared" / "carla")
    ap.add_argument("--out", type=Path, default=ROOT / "networks" / "carla")
    args = ap.parse_args(argv)
    missing = [t for t in TOWNS if not (args.src / f"{t}.net.xml").is_file()]
    if missing or not (args.src / NOTICE).is_file():
        raise SystemExit(f"{args.src}: missing {', '.join(missing) or NOTICE}")
    args.out.mkdir(parents=True, exist_ok=True)
    for town in TOWNS:
        convert(args.src / f"{town}.net.xml", args.out / f"{town}.net.xml")
        print(f"{args.out / town}.net.xml")
    shutil.copyfile(args.src / NOTICE, args.out / NOTICE)
    write_atomic(args.out / "README.md", README)
    return 0


if __name__ == "__main__":
    sys.exit(main())
