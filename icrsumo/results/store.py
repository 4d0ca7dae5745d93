"""The results store of an evaluation: one SQLite file, one row per finished episode.

Each episode is committed on its own (``synchronous=FULL``), so a run killed at any moment
(even with SIGKILL) loses at most the episodes in flight; rerunning resumes from what is here.
Only the evaluating process writes; workers return results to it.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import sqlite3
import zlib
from collections.abc import Collection, Iterator, Mapping
from dataclasses import asdict, fields
from pathlib import Path

from icrsumo.core.errors import Field, InputError
from icrsumo.core.types import EpisodeLog, EpisodeRecord
from icrsumo.core.vocab import EpisodeStatus, EventKind, Family, Termination, TerminationClass

_COLUMNS = [f.name for f in fields(EpisodeRecord)]
_SCHEMA = """
CREATE TABLE IF NOT EXISTS episodes (
    agent TEXT NOT NULL, route_id TEXT NOT NULL, family TEXT NOT NULL, k INTEGER NOT NULL,
    seed INTEGER NOT NULL, status TEXT NOT NULL, ds REAL, rc REAL, is_ REAL, termination TEXT,
    termination_class TEXT, infractions TEXT, length REAL, duration REAL, attempts INTEGER,
    message TEXT, log BLOB, outside_m REAL DEFAULT 0, fingerprint TEXT DEFAULT '',
    model_calls INTEGER DEFAULT 0, invalid_answers INTEGER DEFAULT 0,
    guard_checked INTEGER DEFAULT 0, guard_blocked INTEGER DEFAULT 0,
    PRIMARY KEY (agent, route_id, family, k, seed)
);
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
"""

#: integer columns that count things (0 when a store written before them has NULL)
_COUNTS = ("model_calls", "invalid_answers", "guard_checked", "guard_blocked")
#: counts a store has only once an episode with one of their group was stored (asks for
#: clarification, repairs of a guard: a store of runs without them keeps the columns it always
#: had); 0 where absent
_LATE_GROUPS = (("asks", "asks_answered"), ("guard_repaired",))
_LATE_COUNTS = tuple(c for group in _LATE_GROUPS for c in group)

#: bytes free under which an SQLite I/O error is taken as the disk being full
_FULL_BELOW = 1 << 20


def _disk_full(err: sqlite3.Error, path: Path) -> bool:
    """Whether SQLite failed for want of space: SQLITE_FULL, or an I/O error while the disk that
    holds ``path`` has less than 1 MiB free (SQLite reports a full disk either way)."""
    code = getattr(err, "sqlite_errorcode", None)
    if code == 13 or "disk is full" in str(err):
        return True
    if code is not None and code & 0xFF != 10 and "disk I/O error" not in str(err):
        return False
    try:
        st = os.statvfs(Path(path).parent)
    except OSError:
        return False
    return st.f_bavail * st.f_frsize < _FULL_BELOW


def _not_writable(err: sqlite3.Error, path: Path) -> bool:
    """Whether SQLite failed because the store (or its folder, where SQLite makes its journal)
    may not be written: SQLITE_READONLY, or SQLITE_CANTOPEN / an I/O error while the file or its
    folder is not writable (a read-only disk, missing permissions)."""
    code = getattr(err, "sqlite_errorcode", None)
    primary = None if code is None else code & 0xFF
    if primary == 8 or "readonly database" in str(err):
        return True
    if primary not in (10, 14) and "unable to open" not in str(err):
        return False
    path = Path(path)
    return not os.access(path.parent, os.W_OK | os.X_OK) or (path.exists() and not os.access(path, os.W_OK))


class ResultStore:
    """Episode records (and compressed episode logs) keyed by (agent, route, family, k, seed)."""

    def __init__(self, path: Path, verify: bool = True, readonly: bool = False) -> None:
        """Open (or create) the store at ``path``; an existing file is checked first
        (``PRAGMA quick_check``, which reads every page: ``verify=False`` skips it for a store
        that :meth:`check` has just passed). ``readonly``: open an existing store for reading
        only, which also works in a folder this process may not write (a read-only disk or
        copy); nothing is created or changed."""
        self.path = Path(path)
        existed = self.path.exists()
        if existed and not self.path.is_file():
            raise InputError(self.path, "", "is not a file", "move it away: the results store is a file")
        if readonly:
            self._db = self._open_readonly()
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(str(self.path))
        with self._guard("opening"):
            if existed:  # checked before anything is written to it (journal mode included)
                bad = [r[0] for r in self._db.execute("PRAGMA quick_check")] if verify else ["ok"]
                if bad != ["ok"]:
                    raise sqlite3.DatabaseError(bad[0])
                tables = {r[0] for r in self._db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
                if tables and "episodes" not in tables:
                    shown = ", ".join(sorted(tables))[:80]
                    raise sqlite3.DatabaseError(f"no episodes table (tables: {shown})")
                if readonly and not tables:
                    raise sqlite3.DatabaseError("no episodes table (an empty file)")
            if not readonly:
                self._db.execute("PRAGMA journal_mode=WAL")
                self._db.execute("PRAGMA synchronous=FULL")
                self._db.executescript(_SCHEMA)
                self._db.commit()
            #: the episodes table's columns (a store written before ``outside_m`` or
            #: ``fingerprint`` lacks them until the first write adds them)
            self._cols = {r[1] for r in self._db.execute("PRAGMA table_info(episodes)")}
        #: agent name -> fingerprint of the agents this run drives (:meth:`claim_agents`)
        self._claimed: dict[str, str] = {}

    def _open_readonly(self) -> sqlite3.Connection:
        """A read-only connection (SQLite's ``mode=ro``). Where the folder cannot be written,
        SQLite cannot make the files a reader of a WAL store needs, so the store is opened as
        immutable: no other process can change it there either. A write-ahead log left beside
        it (a run that was killed) holds episodes such an open would miss: an InputError."""
        from urllib.parse import quote

        if not self.path.is_file():
            raise InputError(self.path, "", "the results store is missing",
                             "give the out folder of an evaluation (it holds results.sqlite)")
        uri = f"file:{quote(str(self.path.resolve()))}?mode=ro"
        if not os.access(self.path.parent, os.W_OK | os.X_OK):
            wal = self.path.with_name(self.path.name + "-wal")
            if wal.is_file() and wal.stat().st_size > 0:
                raise InputError(self.path, "opening", f"the folder is not writable and {wal.name} holds "
                                 "episodes not yet merged into the store, which reading needs a writable "
                                 "folder for", "make the folder writable (or copy it somewhere writable) "
                                 "and run the command there")
            uri += "&immutable=1"
        try:
            return sqlite3.connect(uri, uri=True)
        except sqlite3.Error as err:
            raise InputError(self.path, "opening", f"cannot be opened for reading ({err})",
                             "check the file's permissions") from None

    @staticmethod
    def check(path: Path) -> None:
        """An InputError if a store exists at ``path`` and cannot be read (nothing is created)."""
        if Path(path).exists():
            ResultStore(path).close()

    @contextlib.contextmanager
    def _guard(self, doing: str) -> Iterator[None]:
        """SQLite's errors as one InputError naming the store: a full disk as such (the store is
        healthy: never a fix that discards it), anything else as a damaged file."""
        try:
            yield
        except sqlite3.DatabaseError as err:
            with contextlib.suppress(sqlite3.Error):
                self._db.close()
            if _not_writable(err, self.path):
                raise InputError(self.path, doing, "the results store or its folder is not writable "
                                 "(read-only disk, or no write permission); the store itself is intact",
                                 "make the folder and results.sqlite writable (or copy the folder somewhere "
                                 "writable) and run the same command again") from None
            if _disk_full(err, self.path):
                raise InputError(self.path, doing, "no space left on the disk that holds the results "
                                 "store (the store and every episode in it are intact)",
                                 "free space on that disk and run the same command again (it resumes)",
                                 ) from None
            raise InputError(self.path, doing, f"the results store is damaged or not an icrsumo store "
                             f"({err})", "restore it from a copy, or move it away and rerun (its episodes "
                             "are then run again)") from None

    def close(self) -> None:
        self._db.close()

    def __enter__(self) -> ResultStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ----------------------------------------------------------------- meta
    def get_meta(self, key: str) -> str | None:
        with self._guard("reading"):
            row = self._db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return None if row is None else row[0]

    def set_meta(self, key: str, value: str) -> None:
        with self._guard("writing"):
            self._db.execute("INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (key, value))
            self._db.commit()

    # ----------------------------------------------------------------- agent identity
    def agent_fingerprints(self) -> dict[str, set[str]]:
        """Agent name -> the fingerprints its stored episodes carry ("" for episodes stored
        before icrsumo kept fingerprints)."""
        if "fingerprint" not in self._cols:
            with self._guard("reading"):
                return {a: {""} for (a,) in self._db.execute("SELECT DISTINCT agent FROM episodes")}
        out: dict[str, set[str]] = {}
        with self._guard("reading"):
            for agent, fp in self._db.execute("SELECT DISTINCT agent, fingerprint FROM episodes"):
                out.setdefault(agent, set()).add(fp or "")
        return out

    def episode_fingerprint(self, agent: str, route_id: str, family: str, k: int, seed: int) -> str:
        """The fingerprint stored with one episode ("" when it has none or is not stored)."""
        if "fingerprint" not in self._cols:
            return ""
        with self._guard("reading"):
            key = (agent, route_id, str(family), k, seed)
            row = self._db.execute("SELECT fingerprint FROM episodes WHERE agent=? AND route_id=? "
                                   "AND family=? AND k=? AND seed=?", key).fetchone()
        return (row[0] or "") if row else ""

    def check_agents(self, fingerprints: Mapping[str, str], replace: Collection[str] = ()) -> list[str]:
        """An InputError when an agent of ``fingerprints`` (name -> fingerprint) has stored
        episodes of another fingerprint and is not in ``replace``; returns the names whose
        stored episodes carry no fingerprint (stored by an icrsumo before fingerprints)."""
        from icrsumo.agents.identity import short

        unmarked = []
        stored = self.agent_fingerprints()
        for name, fp in fingerprints.items():
            old = stored.get(name, set())
            other = sorted(old - {fp, ""})
            if other and name not in replace:
                raise InputError(self.path, f"agent {name}", f"holds episodes of another agent of that name "
                                 f"(fingerprint {short(other[0])}; the agent given now is {short(fp)})",
                                 f"use another {Field('out')} folder, or {Field('replace_agents')} {name} "
                                 f"to delete that agent's stored episodes and run it again")
            if "" in old and name not in replace:
                unmarked.append(name)
        return unmarked

    def replaceable(self, fingerprints: Mapping[str, str],
                    replace: Collection[str]) -> dict[str, tuple[int, tuple[str, ...]]]:
        """Name -> (how many stored episodes :meth:`claim_agents` deletes for it, the
        fingerprints they carry, "" for none) for every name in ``replace``: the episodes of the
        name that another agent (not ``fingerprints[name]``) drove."""
        out: dict[str, tuple[int, tuple[str, ...]]] = {}
        with self._guard("reading"):
            for name in replace:
                if "fingerprint" in self._cols:
                    rows = self._db.execute("SELECT fingerprint, COUNT(*) FROM episodes WHERE agent = ? AND "
                                            "fingerprint IS NOT ? GROUP BY fingerprint",
                                            (name, fingerprints.get(name, ""))).fetchall()
                else:
                    rows = self._db.execute("SELECT '', COUNT(*) FROM episodes WHERE agent = ?",
                                            (name,)).fetchall()
                rows = [(fp or "", n) for fp, n in rows if n]
                out[name] = (sum(n for _, n in rows), tuple(sorted({fp for fp, _ in rows})))
        return out

    def claim_agents(self, fingerprints: Mapping[str, str], replace: Collection[str] = ()) -> list[str]:
        """Check (:meth:`check_agents`), delete the stored episodes of the agents in ``replace``
        that another agent of the name drove, and stamp every episode :meth:`put` stores from now
        on with its agent's fingerprint; returns the names of agents whose stored episodes carry
        no fingerprint."""
        unmarked = self.check_agents(fingerprints, replace)
        with self._guard("writing"):
            self._add_columns()
            for name in replace:  # the rows of this very agent (a resumed replacing run) stay
                self._db.execute("DELETE FROM episodes WHERE agent = ? AND fingerprint IS NOT ?",
                                 (name, fingerprints.get(name, "")))
            self._db.commit()
        self._claimed = dict(fingerprints)
        return unmarked

    def _add_columns(self, late: tuple[str, ...] = ()) -> None:
        """The columns a store written by an earlier icrsumo lacks; ``late``: those of the
        :data:`_LATE_COUNTS` too."""
        for col, decl in (("outside_m", "REAL DEFAULT 0"), ("fingerprint", "TEXT DEFAULT ''"),
                          *((c, "INTEGER DEFAULT 0") for c in (*_COUNTS, *late))):
            if col not in self._cols:
                self._db.execute(f"ALTER TABLE episodes ADD COLUMN {col} {decl}")
                self._cols.add(col)

    # ----------------------------------------------------------------- episodes
    def put(self, rec: EpisodeRecord, log_json: str | None = None) -> None:
        """Store one finished episode and commit at once."""
        row = asdict(rec)
        row["infractions"] = json.dumps([list(i) for i in rec.infractions])
        row["log"] = zlib.compress(log_json.encode("utf-8"), 6) if log_json else None
        row["fingerprint"] = self._claimed.get(rec.agent, "")
        with self._guard("writing"):
            self._add_columns(late=tuple(c for group in _LATE_GROUPS if any(row[x] for x in group)
                                         for c in group))
            cols = [c for c in _COLUMNS if c not in _LATE_COUNTS or c in self._cols] + ["log", "fingerprint"]
            self._db.execute(
                f"INSERT OR REPLACE INTO episodes ({', '.join(cols)}) VALUES ({', '.join('?' * len(cols))})",
                [row[c] for c in cols],
            )
            self._db.commit()

    def keys(self, status: EpisodeStatus | None = None) -> set[tuple[str, str, str, int, int]]:
        """Keys of every stored episode (done or crashed), or of those with ``status``."""
        sql = "SELECT agent, route_id, family, k, seed FROM episodes"
        with self._guard("reading"):
            if status is None:
                return {tuple(r) for r in self._db.execute(sql)}
            return {tuple(r) for r in self._db.execute(sql + " WHERE status = ?", (str(status),))}

    def records(self, family: str | None = None) -> list[EpisodeRecord]:
        """Every stored episode (or those of ``family``), sorted by key."""
        where, args = ("WHERE family = ?", (str(family),)) if family is not None else ("", ())
        with self._guard("reading"):
            cols = [c for c in _COLUMNS if c in self._cols]
            rows = self._db.execute(f"SELECT {', '.join(cols)} FROM episodes {where} "
                                    "ORDER BY agent, route_id, family, k, seed", args).fetchall()
        out = []
        for r in rows:
            d = dict(zip(cols, r))
            if d.get("outside_m") is None:
                d["outside_m"] = 0.0
            for c in (*_COUNTS, *_LATE_COUNTS):
                if d.get(c) is None:
                    d[c] = 0
            try:
                if d["status"] == "done" and None in (d["ds"], d["rc"], d["is_"]):
                    raise TypeError("a finished episode without its scores")
                for c in ("ds", "rc", "is_", "length", "duration", "k", "seed", "attempts", "outside_m",
                          *_COUNTS, *_LATE_COUNTS):
                    if d[c] is not None and (not isinstance(d[c], (int, float)) or not math.isfinite(d[c])):
                        raise TypeError(f"{c} is {d[c]!r}, not a finite number")
                raw = json.loads(d["infractions"] or "[]")
                d["infractions"] = tuple((EventKind(k), float(f)) for k, f in raw)
                d["status"], d["family"] = EpisodeStatus(d["status"]), Family(d["family"])
                term, cls = d["termination"], d["termination_class"]
                d["termination"] = Termination(term) if term else ""
                d["termination_class"] = TerminationClass(cls) if cls else ""
            except (ValueError, TypeError) as err:
                key = "/".join(str(d[k]) for k in ("agent", "route_id", "family", "k", "seed"))
                raise InputError(self.path, f"episode {key}", f"holds an unknown value ({err})",
                                 "the store is damaged: move it away and rerun the evaluation") from None
            out.append(EpisodeRecord(**d))
        return out

    def episode_log(self, agent: str, route_id: str, family: str, k: int, seed: int) -> EpisodeLog | None:
        """The stored episode log of one episode, parsed (None when there is none); a damaged
        one is an InputError naming the store and the episode."""
        from .logs import loads_log

        text = self.log(agent, route_id, family, k, seed)
        if text is None:
            return None
        try:
            return loads_log(text)
        except (InputError, ValueError, TypeError, KeyError, RecursionError) as err:
            why = err.problem if isinstance(err, InputError) else f"{type(err).__name__}: {err}"
            raise InputError(self.path, f"episode {agent}/{route_id}/{family}/{k}/{seed}",
                             f"its stored log is damaged ({' '.join(str(why).split())[:160]})",
                             "delete that row (or move the store away) and rerun") from None

    def log(self, agent: str, route_id: str, family: str, k: int, seed: int) -> str | None:
        """The stored episode log (JSON text) of one episode, if any."""
        with self._guard("reading"):
            row = self._db.execute(
                "SELECT log FROM episodes WHERE agent=? AND route_id=? AND family=? AND k=? AND seed=?",
                (agent, route_id, family, k, seed)).fetchone()
        return None if row is None else self._log_text((agent, route_id, family, k, seed), row[0])

    def _log_text(self, key: tuple, blob: object) -> str | None:
        """The JSON text of a stored log column (None when there is none); a damaged one is an
        InputError naming the episode."""
        if blob is None:
            return None
        try:
            return zlib.decompress(blob).decode("utf-8")
        except (zlib.error, TypeError, UnicodeDecodeError) as err:
            raise InputError(self.path, f"episode {'/'.join(map(str, key))}",
                             f"its stored log is damaged ({err})",
                             "delete that row (or move the store away) and rerun") from None

    def logs(self) -> Iterator[tuple[tuple, str, str, str | None]]:
        """Every stored episode as (key, status, message, log JSON text or None), in the
        store's order, read by one query (a consistent snapshot, also while a run is storing
        episodes): what :mod:`icrsumo.evaluation.digests` hashes. Values are as stored (the caller checks
        their types); a damaged log is an InputError naming the episode."""
        sql = "SELECT agent, route_id, family, k, seed, status, message, log FROM episodes"
        with self._guard("reading"):
            for *key, status, message, blob in self._db.execute(sql):
                yield tuple(key), status, message, self._log_text(tuple(key), blob)
