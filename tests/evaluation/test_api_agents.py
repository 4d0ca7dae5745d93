"""The Python API takes agents as Python objects: a class, a function that makes agents and an
instance, beside a spec, in one in-process evaluation; its errors speak of keyword arguments."""

from __future__ import annotations

import json

import numpy as np
import pytest

import icrsumo
import icrsumo.results.store
from icrsumo.agents.base import Action
from icrsumo.core.errors import InputError

pytestmark = pytest.mark.sumo


class Cruise:
    """Drives straight on at ``speed`` m/s whatever it is told."""

    name = "cruise"
    privileged = False

    def __init__(self, speed: float = 5.0, name: str | None = None) -> None:
        self.speed = speed
        if name:
            self.name = name
        self.resets = 0

    def reset(self, info) -> None:
        self.resets += 1

    def act(self, obs) -> Action:
        return Action(waypoints=np.array([[2.5, 0.0], [5.0, 0.0], [7.5, 0.0]]), target_speed=self.speed)


def make_fast():
    """A function that makes agents."""
    return Cruise(7.0, name="cruise-fast")


def test_classes_functions_instances_and_specs_in_one_run(tmp_path):
    slow, mid = Cruise(3.0, name="cruise-slow"), Cruise(4.0, name="cruise-mid")  # two instances of one class
    kw = dict(suite="tiny", families="misleading", k=1, routes=["tiny_003"], out=tmp_path, workers=2)
    run = icrsumo.evaluate(agents=[Cruise, make_fast, slow, mid, "route-oracle"], **kw)
    assert (run.episodes, run.done, run.crashed) == (10, 10, 0)
    assert set(run.summary["agents"]) == {"cruise", "cruise-fast", "cruise-slow", "cruise-mid",
                                          "route-oracle"}
    assert slow.resets == 0  # every episode drove a fresh copy of the instance
    agents = json.loads((tmp_path / "config.json").read_text())["agents"]
    assert agents["cruise"]["spec"].startswith("python:") and agents["cruise"]["spec"].endswith("Cruise")
    with icrsumo.results.store.ResultStore(tmp_path / "results.sqlite") as store:
        took = {r.agent: r.duration for r in store.records() if r.family == "baseline"}
    assert took["cruise-slow"] > took["cruise"] > took["cruise-fast"]  # three speeds, three agents driven
    again = icrsumo.evaluate(agents=[Cruise, make_fast, slow, mid, "route-oracle"], **kw)
    assert again.ran == 0 and again.summary == run.summary


@pytest.mark.parametrize("agents, expect", [
    ([object()], "agents[0]: <object object at"),
    (["no-such-agent"], "agents: no-such-agent: not a built-in agent nor MODULE:CLASS (fix: use one of"),
])
def test_errors_name_the_keyword_arguments(tmp_path, agents, expect):
    with pytest.raises(InputError) as err:
        icrsumo.evaluate(agents=agents, suite="tiny", k=1, out=tmp_path / "o", workers=1)
    assert str(err.value).startswith(expect) and "--agent" not in str(err.value)
    assert not (tmp_path / "o").exists()
