"""The run digest (icrsumo.evaluation.digests, ``icrsumo digest``): its byte format by hand, independent of
insertion order, compared between folders and with digest strings, and refused in one line
where there is nothing to compare. Hand-made stores, no SUMO (tests/evaluation/test_evaluate.py
checks it on real runs: summary.json, worker counts, the evaluation's last line)."""

from __future__ import annotations

import hashlib
import json
import sqlite3
import zlib
from pathlib import Path

import pytest

import icrsumo
from icrsumo.app.cli.main import main
from icrsumo.core.errors import InputError
from icrsumo.core.types import EpisodeRecord
from icrsumo.core.vocab import EpisodeStatus
from icrsumo.evaluation.digests import digest_lines, folder_digest, parse_digest, run_digest, store_hashes
from icrsumo.results.store import ResultStore

LOG_A = '{"version": 2, "route_id": "r1", "x": [1.5]}\n'
LOG_B = '{"version": 2, "route_id": "r2", "x": [2.5]}\n'


def _done(agent: str, route: str, family: str = "baseline", k: int = 0) -> EpisodeRecord:
    return EpisodeRecord(agent, route, family, k, 2026, EpisodeStatus.DONE, ds=100.0, rc=100.0, is_=1.0,
                         termination="route_completed", termination_class="done")


#: (record, log text) in the order they are stored: not the key order
EPISODES = [
    (_done("oracle", "r2"), LOG_B),
    (EpisodeRecord("oracle", "r1", "misleading", 0, 2026, EpisodeStatus.CRASHED,
                   message="boom\nat x.py:3"), None),
    (_done("oracle", "r1"), LOG_A),
]


def _folder(path: Path, episodes=EPISODES, **config) -> Path:
    """An evaluation folder: config.json and a store holding ``episodes`` (in that order)."""
    path.mkdir(parents=True)
    cfg = {"suite": "tiny", "seed": 2026, "k": 1, "traffic": "normal", "scoring": "lb1", **config}
    (path / "config.json").write_text(json.dumps(cfg))
    with ResultStore(path / "results.sqlite") as store:
        for rec, log in episodes:
            store.put(rec, log)
    return path


def _sha(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def test_the_byte_format_by_hand(tmp_path):
    """The lines are exactly the documented ones: header, then the episodes by key, each with the
    SHA-256 of its log text (a crashed one: of [status, message]); any insertion order gives
    the same digest."""
    out = _folder(tmp_path / "a")
    crashed = _sha('["crashed","boom\\nat x.py:3"]')
    expected = ('["icrsumo-digest",1,"lb1"]\n'
                f'["oracle","r1","baseline",0,2026,"log","{_sha(LOG_A)}"]\n'
                f'["oracle","r1","misleading",0,2026,"no-log","{crashed}"]\n'
                f'["oracle","r2","baseline",0,2026,"log","{_sha(LOG_B)}"]\n').encode("ascii")
    with ResultStore(out / "results.sqlite") as store:
        assert b"".join(digest_lines(store_hashes(store), "lb1")) == expected
        digest = run_digest(store, "lb1")
    assert digest == "sha256:" + hashlib.sha256(expected).hexdigest()
    assert run_digest(out / "results.sqlite", "lb1") == digest
    assert run_digest(out / "results.sqlite", "lb2") != digest            # the scoring is part of it
    other = _folder(tmp_path / "b", episodes=list(reversed(EPISODES)))   # another insertion order
    assert run_digest(other / "results.sqlite", "lb1") == digest
    # non-ASCII names are escaped, so the lines stay ASCII
    with ResultStore(_folder(tmp_path / "c", [(_done("é", "r"), LOG_A)]) / "results.sqlite") as store:
        lines = digest_lines(store_hashes(store), "lb1")
    assert lines[1].startswith(b'["\\u00e9","r",')


def test_digest_prints_the_stores_digest_and_checks_the_summary(tmp_path, capsys):
    out = _folder(tmp_path / "a")
    digest = run_digest(out / "results.sqlite", "lb1")
    assert main(["digest", str(out)]) == 0
    got = capsys.readouterr()
    assert got.out == f"{digest}\n" and "3 stored episodes, scoring lb1" in got.err
    assert "summary.json is missing" in got.err
    (out / "summary.json").write_text(json.dumps({"scoring": "lb1", "digest": digest}))
    assert main(["digest", str(out)]) == 0
    assert "summary.json holds the same digest" in capsys.readouterr().err
    (out / "summary.json").write_text(json.dumps({"scoring": "lb1", "digest": "sha256:" + "0" * 64}))
    assert main(["digest", str(out)]) == 0
    got = capsys.readouterr()
    assert got.out == f"{digest}\n" and "is not the store's" in got.err       # never taken from it
    assert icrsumo.digest(out) == digest


def test_two_folders_same_and_the_first_differing_episode(tmp_path, capsys):
    a = _folder(tmp_path / "a")
    b = _folder(tmp_path / "b", episodes=list(reversed(EPISODES)))
    assert main(["digest", str(a), str(b)]) == 0
    assert capsys.readouterr().out.splitlines()[0] == "same"
    with sqlite3.connect(b / "results.sqlite") as db:   # one row's log edited
        db.execute("UPDATE episodes SET log = ? WHERE route_id = 'r2'",
                   (zlib.compress(LOG_B.replace("2.5", "2.6").encode()),))
    assert main(["digest", str(a), str(b)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "differs"
    assert out[-1] == "  first difference: episode oracle/r2/baseline/0/2026: its stored logs differ"
    c = _folder(tmp_path / "c", episodes=EPISODES[1:])  # r2 missing
    assert main(["digest", str(c), str(a)]) == 1
    assert f"episode oracle/r2/baseline/0/2026 is stored in {a} only" in capsys.readouterr().out
    cmp = icrsumo.compare_digests(a, c)
    assert not cmp.same and "is stored in" in cmp.first_difference


def test_a_digest_string_is_compared(tmp_path, capsys):
    a = _folder(tmp_path / "a")
    digest = run_digest(a / "results.sqlite", "lb1")
    for given in (digest, digest.removeprefix("sha256:").upper()):
        assert main(["digest", str(a), given]) == 0
        assert capsys.readouterr().out.splitlines()[0] == "same"
    assert main(["digest", str(a), "sha256:" + "ab" * 32]) == 1
    assert capsys.readouterr().out.splitlines()[0] == "differs"
    assert parse_digest("sha256:" + "g" * 64) is None and parse_digest("ab" * 31) is None


def _one_line_error(capsys, argv: list[str]) -> str:
    code = main(argv)
    got = capsys.readouterr()
    err = got.err.strip().splitlines()
    assert code == 2 and got.out == "" and len(err) == 1 and "Traceback" not in err[0], (code, got)
    return err[0]


def test_what_cannot_be_compared_is_one_line_with_exit_2(tmp_path, capsys):
    a = _folder(tmp_path / "a")
    lb2 = _folder(tmp_path / "lb2", scoring="lb2")
    line = _one_line_error(capsys, ["digest", str(a), str(lb2)])
    assert f"{lb2}/config.json: scoring: is lb2, {a}/config.json's is lb1" in line
    short = _folder(tmp_path / "short", suite="short")
    line = _one_line_error(capsys, ["digest", str(a), str(short)])
    assert "suite: is 'short'" in line and "different suites are not compared" in line
    line = _one_line_error(capsys, ["digest", str(a), "sha256:1234"])
    assert "is neither an existing evaluation folder nor a digest" in line
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "config.json").write_text((a / "config.json").read_text())
    line = _one_line_error(capsys, ["digest", str(empty)])
    assert "results.sqlite: is missing" in line
    line = _one_line_error(capsys, ["digest", str(a), str(empty)])
    assert "results.sqlite: is missing" in line
    # the library's words name no command-line option
    with pytest.raises(InputError) as err:
        icrsumo.digest(empty)
    assert "--out" not in str(err.value) and "out folder" in str(err.value)
    with pytest.raises(InputError, match="different suites"):
        icrsumo.compare_digests(a, short)


def test_a_damaged_log_is_named_and_the_folder_has_no_digest(tmp_path, capsys):
    a = _folder(tmp_path / "a")
    with sqlite3.connect(a / "results.sqlite") as db:
        db.execute("UPDATE episodes SET log = x'00010203' WHERE route_id = 'r2'")
    line = _one_line_error(capsys, ["digest", str(a)])
    assert "episode oracle/r2/baseline/0/2026: its stored log is damaged" in line
    with pytest.raises(InputError, match="its stored log is damaged"):
        folder_digest(a)
