"""Text no HTTP header or file can carry is refused where it is read, in one line naming the
file or variable, the place and the fix: a shared key that is not printable ASCII (the key
itself never shown), and a lone surrogate (a ``\\ud800`` escape without its pair) in a bank's
phrasing."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

from icrsumo.core.errors import InputError
from icrsumo.core.resources import data_dir
from icrsumo.instructions.banks import load_banks

KEY = "ключ-✓"


def _icrsumo(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "icrsumo", *args], capture_output=True, text=True,
                          timeout=120, env={**os.environ, **(env or {})})


def _one_line(p: subprocess.CompletedProcess) -> str:
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(lines) == 1 and "Traceback" not in p.stderr, p.stderr
    return lines[0]


def test_a_shared_key_that_is_not_ascii_is_named_on_both_sides(tmp_path):
    out = tmp_path / "out"
    line = _one_line(_icrsumo("evaluate", "--agent", "remote:http://127.0.0.1:9?key_env=ICR_KEY", "--routes",
                              "tiny_003", "--k", "1", "--quiet", "--out", str(out), env={"ICR_KEY": KEY}))
    assert ("--agent: remote:http://127.0.0.1:9?key_env=ICR_KEY: the key in ICR_KEY holds a character "
            "that is not printable ASCII (character 1 of 6)") in line
    assert "openssl rand -hex 32" in line and KEY not in line and "ключ" not in line and not out.exists()
    line = _one_line(_icrsumo("serve-agent", "bev-ngram", "--port", "0", "--key-env", "ICR_KEY",
                              env={"ICR_KEY": "abc\u00e9"}))
    assert "--key-env: ICR_KEY: the key in ICR_KEY holds a character that is not printable ASCII " \
           "(character 4 of 4)" in line and "abc" not in line.replace("ICR_KEY", "")


@pytest.fixture
def banks(tmp_path):
    folder = tmp_path / "templates"
    shutil.copytree(data_dir("templates"), folder)
    return folder


def test_a_lone_surrogate_in_a_template_bank_is_named_with_its_place(banks):
    path = banks / "paraphrase.json"
    doc = json.loads(path.read_text())
    doc["intents"]["left"]["plain"][0]["text"] += " \ud800"
    path.write_text(json.dumps(doc))                   # ASCII JSON: the surrogate as an escape
    with pytest.raises(InputError) as err:
        load_banks(banks)
    line = err.value.line()
    assert line.startswith(f"{path}: intents.left.plain[0].text: template bank holds a lone surrogate at "
                           "character ")
    assert "write the character itself, or both halves of its pair" in line


def test_a_lone_surrogate_in_a_baseline_bank_is_refused_before_anything_runs(tmp_path):
    bank, out = tmp_path / "dict.json", tmp_path / "out"
    bank.write_text(json.dumps({"0": ["Turn left at the next intersection.", "Go left \udc80 there."]}))
    line = _one_line(_icrsumo("evaluate", "--baseline-bank", str(bank), "--routes", "tiny_003", "--k", "1",
                              "--quiet", "--out", str(out)))
    assert f"error: {bank}: 0[1]: the baseline bank holds a lone surrogate at character 9 " in line
    assert not out.exists()
