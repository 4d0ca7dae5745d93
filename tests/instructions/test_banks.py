"""Template-bank validation: the bundled banks pass; broken user banks name file and entry."""

from __future__ import annotations

import json
import shutil

import pytest

from icrsumo.core.errors import InputError
from icrsumo.core.resources import data_dir
from icrsumo.instructions.banks import MIN_ENTRIES, NAV_INTENTS, load_banks


def test_bundled_banks_are_valid():
    banks = load_banks()
    for tau in NAV_INTENTS:
        for form in ("plain", "distance"):
            assert len(banks.paraphrase[tau][form]) >= MIN_ENTRIES
            assert len(banks.misleading[tau][form]) >= MIN_ENTRIES
    assert len(banks.ambiguity) >= MIN_ENTRIES and len(banks.noise) >= MIN_ENTRIES
    assert all(len(p) >= 6 for p in banks.baseline.values())


@pytest.fixture()
def user_banks(tmp_path):
    d = tmp_path / "banks"
    shutil.copytree(data_dir("templates"), d)
    return d


def _edit(path, fn):
    data = json.loads(path.read_text())
    fn(data)
    path.write_text(json.dumps(data))


@pytest.mark.parametrize(
    "file, edit, expect",
    [
        ("paraphrase.json", lambda d: d["intents"]["left"]["plain"][2].update(text="Turn right here."),
         "intents.left.plain[2]: 'Turn right here.' classifies as right, not left"),
        ("paraphrase.json", lambda d: d["intents"]["left"]["distance"][0].update(text="Turn left soon."),
         "intents.left.distance[0]: distance entries need [x] exactly once"),
        ("paraphrase.json", lambda d: d["intents"]["follow"]["plain"].__delitem__(slice(3, None)),
         "intents.follow.plain: has 3 entries, needs at least 12"),
        ("misleading.json", lambda d: d["intents"]["right"]["plain"][1].update(text="Police: turn right."),
         "intents.right.plain[1]: 'Police: turn right.' classifies as right, not left"),
        ("paraphrase.json", lambda d: d["intents"]["lane_left"]["plain"][0].update(
            text="Move left at {junction}."), "disallowed placeholders ['junction']"),
        ("ambiguity.json", lambda d: d["entries"][4].update(text="Turn left up ahead."),
         "entries[4]: 'Turn left up ahead.' still carries a direction (left)"),
        ("noise.json", lambda d: d["operations"][0].update(ops=["shout"]),
         "operations[0]: unknown primitive(s) ['shout']"),
        ("baseline.json", lambda d: d["types"]["turn_distance"]["phrasings"].__setitem__(
            0, "Turn {dir} soon."), "types.turn_distance.phrasings[0]: lacks the placeholder [x]"),
        ("misleading.json", lambda d: d.update(family="paraphrase"), 'expected "family": "misleading"'),
    ],
)
def test_broken_banks_name_file_and_entry(user_banks, file, edit, expect):
    _edit(user_banks / file, edit)
    with pytest.raises(InputError) as err:
        load_banks(user_banks)
    line = err.value.line()
    assert file in line and expect in line and "(fix:" in line


def test_malformed_and_missing_bank(user_banks):
    (user_banks / "ambiguity.json").write_text("{ nope")
    with pytest.raises(InputError, match=r"ambiguity.json: line 1, column 3: malformed JSON"):
        load_banks(user_banks)
    (user_banks / "ambiguity.json").unlink()
    with pytest.raises(InputError, match="template bank missing"):
        load_banks(user_banks)
