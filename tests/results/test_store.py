"""The results store opened read-only (where the folder cannot be written) and the names of its
errors: a store that may not be written is said to be so, never "damaged"; what a replacement
deletes is counted; file names derived from names are bounded; terminal text is made visible."""

from __future__ import annotations

import pytest

from icrsumo.core.errors import InputError, visible
from icrsumo.core.fsio import bounded_name
from icrsumo.core.types import EpisodeRecord
from icrsumo.core.vocab import EpisodeStatus
from icrsumo.results.store import ResultStore


def _rec(agent: str, k: int = 0) -> EpisodeRecord:
    return EpisodeRecord(agent=agent, route_id="r1", family="baseline", k=k, seed=1,
                         status=EpisodeStatus.DONE, ds=100.0, rc=100.0, is_=1.0)


def test_a_store_opened_read_only_reads_and_names_a_write_as_not_writable(tmp_path):
    path = tmp_path / "results.sqlite"
    with ResultStore(path) as store:
        store.put(_rec("a"))
    before = path.read_bytes()
    with ResultStore(path, readonly=True) as store:
        assert [r.agent for r in store.records()] == ["a"]
        with pytest.raises(InputError) as err:
            store.set_meta("key", "value")       # SQLite: attempt to write a readonly database
    line = err.value.line()
    assert "is not writable" in line and "the store itself is intact" in line
    assert "damaged" not in line and "move it away" not in line
    assert path.read_bytes() == before
    with pytest.raises(InputError, match="the results store is missing"):
        ResultStore(tmp_path / "none.sqlite", readonly=True)
    assert not (tmp_path / "none.sqlite").exists()


def test_replaceable_counts_what_a_replacement_deletes(tmp_path):
    old, new = "sha256:" + "a" * 64, "sha256:" + "b" * 64
    with ResultStore(tmp_path / "results.sqlite") as store:
        store.claim_agents({"keyword": old})
        store.put(_rec("keyword"))
        store.put(_rec("keyword", 1))
        assert store.replaceable({"keyword": new}, ("keyword",)) == {"keyword": (2, (old,))}
        store.claim_agents({"keyword": new}, replace=("keyword",))
        assert store.replaceable({"keyword": new}, ("keyword",)) == {"keyword": (0, ())}


def test_file_names_of_names_are_bounded_and_stay_apart():
    assert bounded_name("short") == "short"
    a, b = bounded_name("x" * 300 + "a"), bounded_name("x" * 300 + "b")
    assert len(a) == len(b) == 120 and a != b and a.startswith("x" * 100)


def test_terminal_text_shows_control_characters_written_out():
    assert visible("a\x1b]52;c;aGk=\x07\x1b[2J") == "a\\x1b]52;c;aGk=\\x07\\x1b[2J"
    assert visible("tab\tline\n\u202eevil\ud800") == "tab\\tline\\n\\u202eevil\\ud800"
    assert visible("route é ✓ 日本 | ok") == "route é ✓ 日本 | ok"
    assert InputError("f\x1b[2J", "p", "bad\x07").line() == "f\\x1b[2J: p: bad\\x07"


def test_ask_counts_are_stored_and_a_store_without_asks_keeps_its_columns(tmp_path):
    """The ask columns appear with the first episode that asked: a store of runs without asking
    has the columns it always had (its rows read 0 asks); one with asks keeps their counts."""
    import sqlite3
    from dataclasses import replace

    path = tmp_path / "results.sqlite"

    def columns() -> list[str]:
        with sqlite3.connect(path) as c:
            return [r[1] for r in c.execute("PRAGMA table_info(episodes)")]

    with ResultStore(path) as store:
        store.put(_rec("plain"))
        before = columns()
        assert "asks" not in before and "asks_answered" not in before
        assert (store.records()[0].asks, store.records()[0].asks_answered) == (0, 0)
        store.put(replace(_rec("asker"), asks=7, asks_answered=2))
        store.put(_rec("plain", k=1))
    assert columns() == [*before, "asks", "asks_answered"]
    with ResultStore(path, readonly=True) as store:
        got = {(r.agent, r.k): (r.asks, r.asks_answered) for r in store.records()}
    assert got == {("asker", 0): (7, 2), ("plain", 0): (0, 0), ("plain", 1): (0, 0)}


def test_repair_counts_are_stored_and_a_store_without_repairs_keeps_its_columns(tmp_path):
    """``guard_repaired`` appears with the first episode a guard repaired (and not with asks)."""
    import sqlite3
    from dataclasses import replace

    path = tmp_path / "results.sqlite"

    def columns() -> list[str]:
        with sqlite3.connect(path) as c:
            return [r[1] for r in c.execute("PRAGMA table_info(episodes)")]

    with ResultStore(path) as store:
        store.put(_rec("plain"))
        store.put(replace(_rec("asker"), asks=1))
        before = columns()
        assert "guard_repaired" not in before and "asks" in before
        store.put(replace(_rec("a+guard:plan+navigator"), guard_checked=2, guard_blocked=2, guard_repaired=2))
    assert columns() == [*before, "guard_repaired"]
    with ResultStore(path, readonly=True) as store:
        got = {r.agent: r.guard_repaired for r in store.records()}
    assert got == {"plain": 0, "asker": 0, "a+guard:plan+navigator": 2}
