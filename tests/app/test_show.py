"""icrsumo show: a stored episode replayed byte for byte, its video and still written; a log that
is not what the agent drives is reported; bad input is one line."""

from __future__ import annotations

import sqlite3
import zlib

import cv2
import pytest

from icrsumo.app.cli.main import main
from icrsumo.core.vocab import DecisionOutcome, Intent
from icrsumo.instructions.store import read_route_file
from icrsumo.results.decisions import classify_decisions, divergence, turn_of
from icrsumo.results.store import ResultStore

pytestmark = pytest.mark.sumo


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("show") / "out"
    assert main(["evaluate", "--suite", "tiny", "--routes", "tiny_003", "--agent", "route-oracle", "--agent",
                 "instruction-follower", "--family", "misleading", "--k", "1", "--workers", "2", "--quiet",
                 "--out", str(out)]) == 0
    return out


def _decision_left(folder):
    """The stored log of the instruction-follower's misleading k=0 episode on tiny_003 and the
    decision where it left its route."""
    with ResultStore(folder / "results.sqlite") as store:
        log = store.episode_log("instruction-follower", "tiny_003", "misleading", 0, 2026)
    sets, maneuvers = read_route_file(folder / "instructions" / "tiny_003.json")
    iset = next(s for s in sets if (s.family, s.k) == ("misleading", 0))
    return log, divergence(classify_decisions(maneuvers, iset, log))


def test_a_stored_episode_is_replayed_exactly_with_video_and_still(folder, tmp_path, capsys):
    dest = tmp_path / "watch"
    code = main(["show", str(folder), "--agent", "instruction-follower", "--route", "tiny_003",
                 "--family", "misleading", "--k", "0", "--dir", str(dest)])
    out = capsys.readouterr().out
    assert code == 0 and "the replay reproduces the stored log byte for byte" in out
    assert "route_deviation" in out  # a misleading instruction taken: where and why it ended
    video = dest / "episode.webm"
    assert f"video: {video}" in out
    head = video.read_bytes()[:4096]  # WebM (Matroska's EBML magic, DocType webm) holding VP8
    assert head.startswith(b"\x1a\x45\xdf\xa3") and b"webm" in head and b"V_VP8" in head
    cap = cv2.VideoCapture(str(video))
    assert cap.isOpened() and cap.get(cv2.CAP_PROP_FRAME_COUNT) > 50
    still = cv2.imread(str(dest / "moment.png"))
    assert still is not None and still.shape[0] > still.shape[1]  # BEV above, text bands below
    # the still shows the decision: the ego at the junction where it left the route, not yet
    # turned (its heading then is its approach heading), and the turn it made after
    log, left = _decision_left(folder)
    assert left.outcome == DecisionOutcome.FOLLOWED_TEXT
    step = next(i for i, p in enumerate(log.progress) if p >= left.pos)
    assert f"still at t = {log.t[step]:.1f} s (the decision where it left the route: " in out
    approach = next(i for i, p in enumerate(log.progress) if p >= left.pos - 10.0)
    assert turn_of(log.yaw[approach], log.yaw[step]) == Intent.STRAIGHT
    assert turn_of(log.yaw[step], log.yaw[-1]) == left.executed != left.route_intent
    assert log.t[step] < log.t[-1] - 1.0


def test_the_video_plays_in_chromium(folder, tmp_path):
    """The show video decodes in a real browser's <video> element (a skip only outside CI)."""
    from reporting.test_html import _browser

    driver = _browser()  # first: a skip costs no replay
    try:
        dest = tmp_path / "watch"
        assert main(["show", str(folder), "--agent", "route-oracle", "--route", "tiny_003",
                     "--dir", str(dest)]) == 0
        page = dest / "play.html"
        page.write_text('<video id="v" src="episode.webm" muted></video>', encoding="utf-8")
        driver.set_script_timeout(90)
        driver.get(page.as_uri())
        state = driver.execute_async_script(
            "const done = arguments[0], v = document.getElementById('v');"
            "const report = () => done({ready: v.readyState, width: v.videoWidth,"
            " error: v.error && v.error.code});"
            "if (v.readyState >= 2) report(); else { v.addEventListener('loadeddata', report);"
            " v.addEventListener('error', report); setTimeout(report, 30000); }")
    finally:
        driver.quit()
    assert state["error"] is None and state["ready"] >= 2 and state["width"] == 512, state


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
