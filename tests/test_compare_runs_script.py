"""tools/compare_runs.py --effect (docs/scoring.md, "Loop versions") on a real stored run: a folder
against itself drives the same paths and changes nothing; against a copy whose stored log gained
static contacts, the counted static collisions rise."""

import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import icrsumo
from icrsumo.core.types import Event
from icrsumo.results.logs import dumps_log
from icrsumo.results.store import ResultStore

SCRIPT = Path(__file__).resolve().parents[1] / "tools" / "compare_runs.py"
sys.path.insert(0, str(SCRIPT.parent))

import compare_runs  # noqa: E402


def test_effect_of_a_folder_on_itself_and_on_added_static_contacts(tmp_path):
    out = tmp_path / "run"
    icrsumo.evaluate(agents="instruction-follower", families="misleading", k=1, routes=["tiny_003"],
                     out=out, workers=1)
    (base, mis) = compare_runs.effect(out, out)
    assert (base["family"], base["n"], base["same_path"], base["ds_changed"]) == ("baseline", 1, 1, 0)
    assert mis["ds"][0] == mis["ds"][1] and mis["collision_static"] == (0, 0)
    other = tmp_path / "other"
    shutil.copytree(out, other)
    with ResultStore(other / "results.sqlite") as store:
        rec = next(r for r in store.records() if r.family == "baseline")
        log = store.episode_log(rec.agent, rec.route_id, rec.family, rec.k, rec.seed)
        # two contacts 10 m apart: CollisionTest counts both
        i, j = 20, next(j for j in range(len(log.x)) if log.progress[j] > log.progress[20] + 10.0)
        hits = tuple(Event("collision_static", log.t[n], log.progress[n], "roadside", log.x[n], log.y[n])
                     for n in (i, j))
        store.put(replace(rec, ds=rec.ds * 0.65 ** 2, is_=rec.is_ * 0.65 ** 2),
                  dumps_log(replace(log, events=tuple(sorted(log.events + hits, key=lambda e: e.t)))))
    rows = {r["family"]: r for r in compare_runs.effect(out, other)}
    assert rows["baseline"]["collision_static"] == (0, 2) and rows["baseline"]["ds_changed"] == 1
    assert rows["baseline"]["same_path"] == 1 and rows["misleading"]["ds_changed"] == 0
    p = subprocess.run([sys.executable, str(SCRIPT), str(out), str(other), "--effect"], capture_output=True,
                       text=True, timeout=120)
    assert p.returncode == 0 and "| instruction-follower | baseline | 1 | 1 | 1 |" in p.stdout
