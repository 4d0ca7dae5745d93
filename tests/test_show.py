"""icrsumo show: a stored episode replayed byte for byte, its video and still written; a log that
is not what the agent drives is reported; bad input is one line."""

from __future__ import annotations

import sqlite3
import zlib

import cv2
import pytest

from icrsumo.cli import main

pytestmark = pytest.mark.sumo


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("show") / "out"
    assert main(["evaluate", "--suite", "tiny", "--routes", "tiny_003", "--agent", "route-oracle", "--agent",
                 "instruction-follower", "--family", "misleading", "--k", "1", "--workers", "2", "--quiet",
                 "--out", str(out)]) == 0
    return out


def test_a_stored_episode_is_replayed_exactly_with_video_and_still(folder, tmp_path, capsys):
    dest = tmp_path / "watch"
    code = main(["show", str(folder), "--agent", "instruction-follower", "--route", "tiny_003",
                 "--family", "misleading", "--k", "0", "--dir", str(dest)])
    out = capsys.readouterr().out
    assert code == 0 and "the replay reproduces the stored log byte for byte" in out
    assert "route_deviation" in out  # a misleading instruction taken: where and why it ended
    video = next(dest.glob("episode.*"))
    cap = cv2.VideoCapture(str(video))
    assert cap.isOpened() and cap.get(cv2.CAP_PROP_FRAME_COUNT) > 50
    still = cv2.imread(str(dest / "moment.png"))
    assert still is not None and still.shape[0] > still.shape[1]  # BEV above, text bands below


def test_a_stored_log_that_the_agent_does_not_drive_is_reported(folder, tmp_path, capsys):
    db = sqlite3.connect(folder / "results.sqlite")
    try:
        where = "WHERE agent='route-oracle' AND family='baseline'"
        (blob,) = db.execute(f"SELECT log FROM episodes {where}").fetchone()
        text = zlib.decompress(blob).decode()
        tampered = text.replace('"speed": [0.0', '"speed": [0.5', 1)
        assert tampered != text
        db.execute(f"UPDATE episodes SET log=? {where}", (zlib.compress(tampered.encode()),))
        db.commit()
        code = main(["show", str(folder), "--agent", "route-oracle", "--route", "tiny_003",
                     "--dir", str(tmp_path / "w")])
        out = capsys.readouterr().out
        assert code == 1 and "does NOT reproduce the stored log: speed first differs at step 0" in out
    finally:
        db.execute("UPDATE episodes SET log=? WHERE agent='route-oracle' AND family='baseline'", (blob,))
        db.commit()
        db.close()


@pytest.mark.parametrize("argv, expect", [
    (["--agent", "nobody", "--route", "tiny_003"], "--agent: nobody: no stored episode has it (fix: use one"),
    (["--agent", "route-oracle", "--route", "tiny_999"], "--route: tiny_999: no stored episode has it"),
    (["--agent", "route-oracle", "--route", "tiny_003", "--family", "misleading", "--k", "5"],
     "--k: 5: no stored episode of route-oracle on tiny_003 in misleading has it (fix: use one of 0)"),
])
def test_bad_input_is_one_line(folder, capsys, argv, expect):
    assert main(["show", str(folder), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expect in err[0]
