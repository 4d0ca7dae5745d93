"""Collection drives real SUMO with the route-oracle expert (on one tiny-suite route here); the
tests that do use the ``converted`` fixture, which marks them ``sumo`` (conftest)."""

import io
import json

import numpy as np
import pytest

from icrsumo.core.errors import InputError
from icrsumo.core.resources import bundled_suites, suite_coords
from icrsumo.learn.collect import CollectOptions, collect, collect_episode
from icrsumo.world.scenario import find_scenarios


@pytest.fixture(scope="module")
def one_route(converted):
    return str(find_scenarios(converted["tiny"])[0])


def test_collection_is_deterministic_for_a_seed(one_route):
    opts = CollectOptions(every=4)
    a, sa = collect_episode(one_route, 1, opts)
    b, sb = collect_episode(one_route, 1, opts)
    assert a == b and sa == sb
    c, _ = collect_episode(one_route, 1, CollectOptions(every=4, seed=7))
    assert c != a


def test_episode_arrays_and_labels(one_route):
    data, summary = collect_episode(one_route, 1, CollectOptions(every=2))
    z = np.load(io.BytesIO(data))
    n = summary["frames"]
    assert n > 20
    assert z["bev"].shape == (n, 7, 128, 16) and z["bev"].dtype == np.uint8
    bev = np.unpackbits(z["bev"], axis=-1)
    assert bev[:, 0].mean() > 0.05            # drivable area is drawn
    assert z["waypoints"].shape == (n, 8, 2)
    assert np.all(np.diff(z["waypoints"][..., 0], axis=1) > -1.0)   # ahead, mostly increasing
    assert z["target_speed"].max() > 3.0 and z["speed"].max() > 3.0
    assert z["perturbed"].any() and not z["perturbed"].all()   # pass 1 is perturbed
    docs = json.loads(str(z["instructions"]))
    assert docs and all({"text", "type", "intent", "slots"} <= set(d) for d in docs)
    assert set(np.unique(z["instruction"])) <= set(range(-1, len(docs)))
    clean, _ = collect_episode(one_route, 0, CollectOptions(every=2))
    assert not np.load(io.BytesIO(clean))["perturbed"].any()


def test_collect_resumes_and_refuses_other_config(converted, tmp_path):
    opts = CollectOptions(suite=str(converted["tiny"]), passes=1, every=5, limit=1)
    m = collect(opts, tmp_path, quiet=True)
    ep = tmp_path / "episodes" / m["episodes"][0]
    before = ep.stat().st_mtime_ns
    m2 = collect(opts, tmp_path, quiet=True)
    assert m2 == m and ep.stat().st_mtime_ns == before
    with pytest.raises(InputError, match="different configuration"):
        collect(CollectOptions(suite=str(converted["tiny"]), passes=2, every=5, limit=1), tmp_path,
                quiet=True)


@pytest.mark.parametrize("split", ["tiny", "short", "long", "langauto-tiny", "langauto-short",
                                   "langauto-long"])
def test_evaluation_suites_are_refused(tmp_path, split):
    """icrsumo's evaluation splits and LangAuto's tracks, by name or by their file's path (no SUMO:
    refused before anything is converted)."""
    for suite in (split, str(bundled_suites()[split])):
        with pytest.raises(InputError, match="evaluation split"):
            collect(CollectOptions(suite=suite), tmp_path)
    assert not any(tmp_path.iterdir())


def test_training_suites_are_accepted():
    for suite in ("train", "carla-train", "carla-focus"):
        CollectOptions(suite=suite).check()
    # converted in CARLA's frame by collect
    assert suite_coords("carla-train") == suite_coords("carla-focus") == "carla"


def test_dagger_pass_lets_a_learned_agent_drive(one_route):
    from icrsumo.learn.agent import CHECKPOINTS

    shipped = sorted(p.stem for p in CHECKPOINTS.glob("*.pt"))
    opts = CollectOptions(every=4, driver=shipped[0])
    a, sa = collect_episode(one_route, 1, opts)
    z = np.load(io.BytesIO(a))
    assert sa["frames"] > 10 and not z["perturbed"].any()   # the driver is never perturbed
    assert collect_episode(one_route, 1, opts)[0] == a


def test_memory_records_the_text_the_network_reads(one_route):
    """With memory (the default) a frame records "Follow the road." (the last document) exactly
    where a learned agent's InstructionMemory hands its network that text; without, every frame
    records the active instruction, as before."""
    from icrsumo.learn.memory import FOLLOW_TEXT

    on = np.load(io.BytesIO(collect_episode(one_route, 0, CollectOptions(every=1))[0]))
    off = np.load(io.BytesIO(collect_episode(one_route, 0, CollectOptions(every=1, memory=False))[0]))
    docs_on, docs_off = json.loads(str(on["instructions"])), json.loads(str(off["instructions"]))
    assert docs_on[:-1] == docs_off and docs_on[-1]["text"] == FOLLOW_TEXT
    assert docs_on[-1]["intent"] == "follow" and len(on["instruction"]) == len(off["instruction"])
    # the same drive (memory changes records, not driving); the memory replaced some frames ...
    assert np.array_equal(on["waypoints"], off["waypoints"])
    replaced = on["instruction"] != off["instruction"]
    assert replaced.any() and np.all(on["instruction"][replaced] == len(docs_off))
    # ... and only turns, lane changes or distance instructions
    kinds = {docs_off[i]["intent"] for i in off["instruction"][replaced]}
    assert kinds <= {"left", "right", "straight", "lane_left", "lane_right"}
    assert FOLLOW_TEXT not in {docs_off[i]["text"] for i in off["instruction"][replaced]}


def test_old_folders_resume_without_memory(converted, tmp_path):
    """A folder collected before the memory option (its config has no "memory") is resumed by
    --no-memory and refused by the default."""
    opts = CollectOptions(suite=str(converted["tiny"]), passes=1, every=5, limit=1, memory=False)
    collect(opts, tmp_path, quiet=True)
    manifest = tmp_path / "collect.json"
    doc = json.loads(manifest.read_text())
    del doc["config"]["memory"]
    manifest.write_text(json.dumps(doc))
    assert collect(opts, tmp_path, quiet=True)["episodes"] == doc["episodes"]
    with pytest.raises(InputError, match="different configuration"):
        collect(CollectOptions(suite=str(converted["tiny"]), passes=1, every=5, limit=1), tmp_path,
                quiet=True)


def test_varied_leads_change_the_text_not_the_drive(one_route, converted, tmp_path):
    """--vary-leads: the expert's clean drive and its labels are the same; which instruction each
    frame records moves; a folder collected with it resumes only with it."""
    fixed = np.load(io.BytesIO(collect_episode(one_route, 0, CollectOptions(every=2))[0]))
    varied = np.load(io.BytesIO(collect_episode(one_route, 0, CollectOptions(every=2, vary_leads=True))[0]))
    assert np.array_equal(fixed["waypoints"], varied["waypoints"])
    assert np.array_equal(fixed["bev"], varied["bev"])
    docs_f, docs_v = json.loads(str(fixed["instructions"])), json.loads(str(varied["instructions"]))
    texts = lambda z, d: [d[i]["text"] if i >= 0 else "" for i in z["instruction"]]  # noqa: E731
    assert texts(fixed, docs_f) != texts(varied, docs_v)
    assert [d["type"] for d in docs_f] == [d["type"] for d in docs_v]
    opts = CollectOptions(suite=str(converted["tiny"]), passes=1, every=5, limit=1, vary_leads=True)
    collect(opts, tmp_path, quiet=True)
    assert json.loads((tmp_path / "collect.json").read_text())["config"]["vary_leads"] is True
    with pytest.raises(InputError, match="different configuration"):
        collect(CollectOptions(suite=str(converted["tiny"]), passes=1, every=5, limit=1), tmp_path,
                quiet=True)
