"""--baseline-bank is part of an evaluation folder's configuration: its content hash (not its
path) is stored in config.json, and a resume with another file is refused like any other change.
No episode runs here: the folder is prepared by load_suite, and evaluate is refused before it
simulates anything."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import pytest

import icrsumo
from icrsumo.app.cli.main import main
from icrsumo.core.errors import InputError

pytestmark = pytest.mark.sumo

BANK = Path(__file__).parents[1] / "data" / "langauto_style_bank.json"
ROUTES = ("tiny_003", "tiny_012")


@pytest.fixture(scope="module")
def suite(tmp_path_factory) -> Path:
    """Two tiny routes converted without background traffic."""
    from icrsumo.core.resources import bundled_suites
    from icrsumo.world.convert import ConvertOptions, convert_routes
    from icrsumo.world.routes import format_routes, read_routes

    d = tmp_path_factory.mktemp("bank_suite")
    specs, _ = read_routes(bundled_suites()["tiny"])
    (d / "routes.xml").write_text(format_routes([s for s in specs if s.id in ROUTES]))
    rep = convert_routes(d / "routes.xml", d / "conv", ConvertOptions(traffic="none", workers=1))
    assert rep.failures == []
    return d / "conv"


def _other_bank(tmp_path: Path) -> Path:
    data = json.loads(BANK.read_text())
    data["38"] = ["Keep rolling along this road."]
    f = tmp_path / "other.json"
    f.write_text(json.dumps(data))
    return f


def test_config_holds_the_hash_and_another_file_is_refused(suite, tmp_path, capsys):
    out = tmp_path / "out"
    s = icrsumo.load_suite(suite, out, k=1, baseline_bank=BANK)
    sha = hashlib.sha256(BANK.read_bytes()).hexdigest()
    config = json.loads((out / "config.json").read_text())
    assert config["baseline_bank_sha256"] == sha and config["baseline_bank_file"] == str(BANK)
    texts = {i.text for iset in s.instruction_sets.values() for i in iset[0].instructions}
    bank = json.loads(BANK.read_text())
    assert texts & {t for v in bank.values() for t in v}  # the baseline speaks LangAuto's wording
    before = (out / "config.json").read_bytes()

    # the same bytes under another path: the same configuration
    copy = tmp_path / "copy.json"
    shutil.copy(BANK, copy)
    again = icrsumo.load_suite(suite, out, k=1, baseline_bank=copy)
    assert again.instruction_sets == s.instruction_sets

    # another file, or none: refused with exit status 2, one line, the folder left as it was
    (out / "config.json").write_bytes(before)
    instr = {p.name: p.read_bytes() for p in (out / "instructions").glob("*.json")}
    for extra in (["--baseline-bank", str(_other_bank(tmp_path))], []):
        code = main(["evaluate", "--suite", str(suite), "--out", str(out), "--k", "1", "--agent",
                     "route-oracle", "--family", "noise", "--workers", "1", "--quiet", *extra])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1
        assert "different configuration: baseline_bank_sha256=" in err[0] and sha in err[0]
        assert (out / "config.json").read_bytes() == before
        assert {p.name: p.read_bytes() for p in (out / "instructions").glob("*.json")} == instr
        assert not (out / "results.sqlite").exists()
    with pytest.raises(InputError, match="baseline_bank_sha256"):
        icrsumo.evaluate(suite=suite, out=out, k=1, agents="route-oracle", families="noise", workers=1,
                         baseline_bank=_other_bank(tmp_path))


def test_a_folder_made_without_a_bank_refuses_one(suite, tmp_path):
    out = tmp_path / "plain"
    icrsumo.load_suite(suite, out, k=1)
    assert "baseline_bank_sha256" not in json.loads((out / "config.json").read_text())
    with pytest.raises(InputError, match=r"baseline_bank_sha256=None \(now '"):
        icrsumo.load_suite(suite, out, k=1, baseline_bank=BANK)
