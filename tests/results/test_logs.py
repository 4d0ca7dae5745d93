"""Episode log / result JSON: round-trips, byte stability, malformed input."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from icrsumo.core.errors import InputError
from icrsumo.core.types import EpisodeLog, Event, TerminationClass
from icrsumo.results.logs import (
    dumps_log,
    loads_log,
    log_from_dict,
    log_to_dict,
    read_log,
    result_from_dict,
    result_to_dict,
    write_log,
)
from icrsumo.scoring import score_episode


def make_log(**kw) -> EpisodeLog:
    base = dict(
        route_id="town01_r3", agent="lmdrive-like", family="paraphrase", k=4, seed=2026, step_length=0.1,
        route_length=123.45,
        t=(0.1, 0.2, 0.3), x=(1.23, 2.34, -3.45), y=(-0.01, 0.0, 5.67), yaw=(0.1234, -3.1416, 1.5708),
        speed=(0.0, 4.321, 10.5), progress=(0.0, 1.5, 1.5), instruction=(-1, 0, 2), outside=(0, 1, 0),
        route_dist=(0.12, 3.4, 30.01),
        events=(Event("collision_vehicle", 0.2, 1.5, "veh_7", 2.34, 0.0),
                Event("red_light", 0.3, 1.5, ":J3_0_0")),
        termination="route_deviation", termination_t=0.3, message="ünïcode [ok] \"quoted\"",
        route=((0.0, 0.0), (50.0, 0.0), (50.0, 73.45)),
    )
    base.update(kw)
    return EpisodeLog(**base)


def test_round_trip_exact():
    log = make_log()
    assert log_from_dict(log_to_dict(log)) == log
    assert loads_log(dumps_log(log)) == log
    assert log_from_dict(json.loads(json.dumps(log_to_dict(log)))) == log


def test_empty_log_round_trips():
    log = make_log(t=(), x=(), y=(), yaw=(), speed=(), progress=(), instruction=(), outside=(), route_dist=(),
                   events=(), termination="sim_error", termination_t=0.0, message="")
    assert loads_log(dumps_log(log)) == log


def test_rounding_and_key_order():
    log = make_log(t=(0.10000000001, 0.2004, 0.3), x=(1.234999, 2.0, 3.0), yaw=(0.123449, 0.0, 0.0),
                   speed=(0.00049, 1.0, 2.0), y=(-0.004, 0.0, 0.0))
    d = log_to_dict(log)
    assert list(d) == ["version", "route_id", "agent", "family", "k", "seed", "step_length", "route_length",
                       "termination", "termination_t", "message", "route", "steps", "events"]
    assert list(d["steps"]) == ["t", "x", "y", "yaw", "speed", "progress", "instruction", "outside",
                                "route_dist", "traffic_speed", "speed_limit"]
    assert d["steps"]["t"] == [0.1, 0.2, 0.3]
    assert d["steps"]["x"][0] == 1.23
    assert d["steps"]["yaw"][0] == 0.1234
    assert d["steps"]["speed"][0] == 0.0
    assert d["steps"]["y"][0] == 0.0 and str(d["steps"]["y"][0]) == "0.0"  # no "-0.0"
    assert d["events"][0] == ["collision_vehicle", 0.2, 1.5, "veh_7", 2.34, 0.0]


def test_dumps_is_byte_stable():
    log = make_log()
    text = dumps_log(log)
    assert text == dumps_log(loads_log(text))
    assert text == dumps_log(make_log())
    assert text.endswith("\n")
    # one line per column and per event keeps files compact and diffable
    assert '"t": [0.1, 0.2, 0.3]' in text
    assert '["red_light", 0.3, 1.5, ":J3_0_0", 0.0, 0.0]' in text
    # numpy scalars and unrounded noise give the same bytes
    noisy = make_log(x=tuple(np.float64(v) + 1e-9 for v in log.x),
                     t=(0.1 + 2e-12, 0.2, 0.30000000000000004),
                     instruction=tuple(np.int64(v) for v in log.instruction),
                     speed=tuple(np.float32(log.speed)))
    assert dumps_log(noisy) == text


def test_non_finite_values_refused_on_write():
    with pytest.raises(ValueError, match=r"steps.speed\[1\]"):
        log_to_dict(make_log(speed=(0.0, float("nan"), 1.0)))
    with pytest.raises(ValueError, match="column 'x'"):
        log_to_dict(make_log(x=(0.0, 1.0)))


def test_file_round_trip(tmp_path):
    log = make_log()
    p = tmp_path / "logs" / "ep.json"
    write_log(p, log)
    assert read_log(p) == log
    with pytest.raises(InputError, match="cannot read"):
        read_log(tmp_path / "missing.json")


def _bad(mutate) -> InputError:
    d = log_to_dict(make_log())
    d = copy.deepcopy(d)
    mutate(d)
    with pytest.raises(InputError) as info:
        log_from_dict(d, "ep.json")
    return info.value


@pytest.mark.parametrize(("mutate", "place"), [
    (lambda d: d.pop("route_id"), "route_id"),
    (lambda d: d.pop("steps"), "steps"),
    (lambda d: d["steps"].pop("speed"), "steps.speed"),
    (lambda d: d.update(k="4"), "k"),
    (lambda d: d.update(seed=True), "seed"),
    (lambda d: d.update(version=1), "version"),
    (lambda d: d.update(termination="crashed"), "termination"),
    (lambda d: d.update(step_length=0), "step_length"),
    (lambda d: d.update(route_length=-1.0), "route_length"),
    (lambda d: d.update(extra=1), "extra"),
    (lambda d: d["steps"].update(accel=[0, 0, 0]), "steps.accel"),
    (lambda d: d["steps"].update(t="0.1"), "steps.t"),
    (lambda d: d["steps"]["speed"].__setitem__(1, "fast"), "steps.speed[1]"),
    (lambda d: d["steps"]["outside"].__setitem__(2, 16), "steps.outside[2]"),
    (lambda d: d["steps"]["instruction"].__setitem__(0, 1.5), "steps.instruction[0]"),
    (lambda d: d["steps"]["instruction"].__setitem__(1, True), "steps.instruction[1]"),
    (lambda d: d["steps"]["speed"].__setitem__(2, False), "steps.speed[2]"),
    (lambda d: d["steps"]["x"].__setitem__(1, 10 ** 400), "steps.x[1]"),
    (lambda d: d["steps"]["y"].__setitem__(2, float("-inf")), "steps.y[2]"),
    (lambda d: d["steps"]["yaw"].__setitem__(0, float("nan")), "steps.yaw[0]"),
    (lambda d: d["steps"]["outside"].__setitem__(1, -1), "steps.outside[1]"),
    (lambda d: d["steps"]["x"].pop(), "steps.x"),
    (lambda d: d["steps"]["t"].__setitem__(2, 0.2), "steps.t[2]"),
    (lambda d: d["steps"]["progress"].__setitem__(2, 1.0), "steps.progress[2]"),
    (lambda d: d.update(events={}), "events"),
    (lambda d: d["events"].append(["red_light", 0.3]), "events[2]"),
    (lambda d: d["events"][0].__setitem__(0, "collison_vehicle"), "events[0].kind"),
    (lambda d: d["events"][1].__setitem__(3, 7), "events[1].other"),
    (lambda d: d["events"][1].__setitem__(1, None), "events[1].t"),
])
def test_malformed_log_names_the_key(mutate, place):
    err = _bad(mutate)
    assert err.file == "ep.json"
    assert err.place == place
    assert place in str(err)


def test_columns_of_other_number_types_read_as_before():
    """A column read at once (plain ints and floats) and one read value by value (a float or int
    subclass in it) give the same values, all floats in number columns and ints in integer ones."""
    d = log_to_dict(make_log())
    plain = log_from_dict(copy.deepcopy(d))
    odd = copy.deepcopy(d)
    odd["steps"]["x"] = [np.float64(v) for v in odd["steps"]["x"]]
    odd["steps"]["speed"] = [int(v) if float(v).is_integer() else v for v in odd["steps"]["speed"]]
    odd["steps"]["outside"] = [_Int(v) for v in odd["steps"]["outside"]]
    slow = log_from_dict(odd)
    assert slow == plain
    assert all(type(v) is float for v in slow.x + slow.speed)
    assert [type(v) for v in plain.instruction] == [int] * len(plain.instruction)


class _Int(int):
    """An int subclass: read value by value, as before the whole-column read."""


def test_malformed_text():
    with pytest.raises(InputError, match="not valid JSON"):
        loads_log("{", "ep.json")
    with pytest.raises(InputError, match="JSON object"):
        loads_log("[]", "ep.json")
    with pytest.raises(InputError, match="finite"):
        loads_log(dumps_log(make_log()).replace("4.321", "NaN"), "ep.json")


def test_message_is_optional_on_read():
    d = log_to_dict(make_log())
    del d["message"]
    assert log_from_dict(d).message == ""


def test_result_round_trip():
    log = make_log(route_length=10.0)
    res = score_episode(log)
    d = result_to_dict(res)
    assert list(d) == ["route_id", "agent", "family", "k", "rc", "is", "ds", "termination",
                       "termination_class", "outside_lanes_pct", "duration", "outside_m", "infractions"]
    assert d["termination_class"] == "RD"
    # the flagged step passed the dense route's point 2 (1 m of the 2 m advanced): 50 % outside
    assert d["infractions"] == [["collision_vehicle", 0.6, 0.2, 1.5, "veh_7"],
                                ["red_light", 0.7, 0.3, 1.5, ":J3_0_0"],
                                ["outside_route_lanes", 0.5, 0.3, 2.0, "1.000 m"]]
    json.dumps(d, allow_nan=False)
    assert result_from_dict(json.loads(json.dumps(d))) == res
    assert result_from_dict(d).termination_class is TerminationClass.RD


def test_result_malformed():
    d = result_to_dict(score_episode(make_log()))
    with pytest.raises(InputError, match="termination_class"):
        result_from_dict({**d, "termination_class": "TO"})
    with pytest.raises(InputError, match="'is'"):
        result_from_dict({k: v for k, v in d.items() if k != "is"})
    with pytest.raises(InputError, match=r"infractions\[0\]"):
        result_from_dict({**d, "infractions": [["red_light", 0.7]]})



# --------------------------------------------------------------------------- asks for clarification
def test_asks_round_trip_and_logs_without_asks_keep_their_bytes():
    from icrsumo.core.types import Ask
    from icrsumo.results.logs import ask_counts

    plain = make_log()
    assert "asks" not in log_to_dict(plain) and ask_counts(plain) == (0, 0)
    asks = (Ask(0.1, 0.0, True, 0), Ask(0.2, 1.504, False), Ask(0.3, 1.5, True, -1))
    log = make_log(asks=asks)
    d = log_to_dict(log)
    assert list(d)[-1] == "asks" and d["asks"][1] == {"t": 0.2, "progress": 1.5, "answered": False,
                                                      "instruction_id": -1}
    back = loads_log(dumps_log(log))
    assert back.asks == (asks[0], Ask(0.2, 1.5, False, -1), asks[2]) and ask_counts(back) == (3, 2)
    # without asks the text is that of a log written before asks existed
    assert dumps_log(plain) == dumps_log(make_log(asks=()))


@pytest.mark.parametrize(("mutate", "place"), [
    (lambda d: d.update(asks={}), "asks"),
    (lambda d: d.update(asks=[{"t": 0.1, "progress": 0.0, "answered": True}]), "asks[0]"),
    (lambda d: d.update(asks=[{"t": 0.1, "progress": 0.0, "answered": 1, "instruction_id": 0}]),
     "asks[0].answered"),
    (lambda d: d.update(asks=[{"t": "0.1", "progress": 0.0, "answered": True, "instruction_id": 0}]),
     "asks[0].t"),
    (lambda d: d.update(asks=[{"t": 0.1, "progress": 0.0, "answered": True, "instruction_id": 0.5}]),
     "asks[0].instruction_id"),
])
def test_malformed_asks_name_the_key(mutate, place):
    err = _bad(mutate)
    assert err.place == place and place in str(err) and "\n" not in str(err)


# --------------------------------------------------------------------------- a guard's repairs
def test_repair_entries_carry_their_text_and_pass_or_block_entries_keep_their_bytes():
    from icrsumo.core.types import GuardDecision
    from icrsumo.core.vocab import Verdict

    block = GuardDecision(0.1, 0.0, 0, Verdict.BLOCK, "right, but the plan goes left in 24 m")
    repair = GuardDecision(0.2, 1.5, 2, Verdict.REPAIR, "why", "At the T-junction, turn left.", 0)
    d = log_to_dict(make_log(guard=(block, repair)))
    assert d["guard"][0] == {"t": 0.1, "progress": 0.0, "instruction_id": 0, "verdict": "block",
                             "reason": "right, but the plan goes left in 24 m"}
    assert d["guard"][1] == {"t": 0.2, "progress": 1.5, "instruction_id": 2, "verdict": "repair",
                             "reason": "why", "text": "At the T-junction, turn left.", "baseline_id": 0}
    assert loads_log(dumps_log(make_log(guard=(block, repair)))).guard == (block, repair)


@pytest.mark.parametrize(("entry", "place"), [
    ({"t": 0.1, "progress": 0.0, "instruction_id": 0, "verdict": "repair", "reason": ""}, "guard[0]"),
    ({"t": 0.1, "progress": 0.0, "instruction_id": 0, "verdict": "block", "reason": "", "text": "x",
      "baseline_id": -1}, "guard[0]"),
    ({"t": 0.1, "progress": 0.0, "instruction_id": 0, "verdict": "repair", "reason": "", "text": 3,
      "baseline_id": -1}, "guard[0].text"),
    ({"t": 0.1, "progress": 0.0, "instruction_id": 0, "verdict": "repair", "reason": "", "text": "x",
      "baseline_id": 0.5}, "guard[0].baseline_id"),
    ({"t": 0.1, "progress": 0.0, "instruction_id": 0, "verdict": "maybe", "reason": ""}, "guard[0].verdict"),
])
def test_malformed_guard_entries_name_the_key(entry, place):
    err = _bad(lambda d: d.update(guard=[entry]))
    assert err.place == place and "\n" not in str(err)
