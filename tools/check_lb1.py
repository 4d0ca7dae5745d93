"""Rescore every stored episode of an evaluation folder with the leaderboard's code transcribed
independently in tests/lb1_reference.py, and compare with the stored Leaderboard 1.0 scores;
then compare each of the folder's results files (``leaderboard/<agent>_<family>.json``) with
the file the transcription builds from the same records, the routes' key points and the
stored logs of crashed episodes (their criteria's partial run).

    python tools/check_lb1.py OUT [OUT ...]

Prints, per folder, the episodes compared, the largest |difference| of DS, RC and IS, how many
differ by more than 1e-4 and how many terminations disagree; then the results files compared
and the first difference of each that differs (a folder scored by other rules than lb1 has
its files left out). Exit status 1 when anything differs.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import lb1_reference  # noqa: E402

from icrsumo.reporting.cells import file_name  # noqa: E402
from icrsumo.results.store import ResultStore  # noqa: E402


def check_episodes(out: Path, store: ResultStore) -> bool:
    """Every finished episode's scores and termination against its log's transcribed scoring."""
    worst = {"ds": 0.0, "rc": 0.0, "is": 0.0}
    n = off = term = 0
    for r in store.records():
        if r.status != "done":
            continue
        ref = lb1_reference.score(store.episode_log(r.agent, r.route_id, r.family, r.k, r.seed))
        diffs = {"ds": abs(ref["score_composed"] - r.ds), "rc": abs(ref["score_route"] - r.rc),
                 "is": abs(ref["score_penalty"] - r.is_)}
        worst = {k: max(worst[k], v) for k, v in diffs.items()}
        n += 1
        off += any(v > 1e-4 for v in diffs.values())
        term += ref["ended"] not in (str(r.termination), None)
    print(f"{out}: {n} episodes; largest |diff| DS {worst['ds']:.2e}, RC {worst['rc']:.2e}, "
          f"IS {worst['is']:.2e}; {off} beyond 1e-4, {term} terminations differ")
    return off == 0 and term == 0


def key_points(out: Path) -> dict:
    """Route id -> the route file's waypoints, read from the scenario manifests of the folder's
    scenarios (OUT/scenarios, else the suite folder its config names)."""
    cfg = json.loads((out / "config.json").read_text(encoding="utf-8"))
    where = out / "scenarios" if (out / "scenarios").is_dir() else Path(cfg["suite"])
    points = {}
    for manifest in sorted(where.glob("**/scenario.json")) if where.is_dir() else []:
        doc = json.loads(manifest.read_text(encoding="utf-8"))
        if doc.get("waypoints"):
            points[doc["route_id"]] = [tuple(p) for p in doc["waypoints"]]
    return points


def check_files(out: Path, store: ResultStore) -> bool:
    """Each results file of the folder against the transcription's file of the same records
    (and the stored logs of crashed episodes, scored up to the crash)."""
    if json.loads((out / "config.json").read_text(encoding="utf-8")).get("scoring") != "lb1":
        print(f"{out}: results files not compared (not scored by lb1)")
        return True
    records = store.records()
    points = key_points(out)
    keys = [(r.agent, r.route_id, r.family, r.k, r.seed) for r in records if r.status == "crashed"]
    logs = {key: log for key in keys if (log := store.episode_log(*key)) is not None}
    n = bad = 0
    for agent, family in sorted({(r.agent, str(r.family)) for r in records}):
        path = out / "leaderboard" / f"{file_name(agent)}_{file_name(family)}.json"
        if not path.is_file():
            continue
        mine = json.loads(path.read_text(encoding="utf-8"))
        ref = lb1_reference.leaderboard_file([r for r in records if r.agent == agent and r.family == family],
                                             points, logs)
        diffs = lb1_reference.differences(mine, ref)
        n += 1
        if diffs:
            bad += 1
            print(f"  {path.name}: {len(diffs)} differences, first: {diffs[0]}")
    print(f"{out}: {n} results files ({len(points)} routes with key points); {bad} differ")
    return bad == 0


def check(out: Path) -> bool:
    with ResultStore(out / "results.sqlite", readonly=True) as store:
        episodes = check_episodes(out, store)
        files = check_files(out, store)
    return episodes and files


def main() -> int:
    ok = all([check(Path(p)) for p in sys.argv[1:]])
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
