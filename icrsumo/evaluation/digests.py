"""The digest of an evaluation: one SHA-256 over every stored episode and the scoring rules,
which anyone can recompute and compare (``icrsumo digest``; ``summary.json``'s ``digest``; the
last line of ``icrsumo evaluate``). The same digest on another machine means every episode is
the same, byte for byte.

The byte format (version 1), defined by :func:`digest_lines`:

* every line is a JSON array as ``json.dumps(array, ensure_ascii=True, separators=(",", ":"))``
  writes it (ASCII only: other characters as ``\\uXXXX`` escapes, no spaces), then ``\\n``;
* the first line is ``["icrsumo-digest",1,SCORING]``, SCORING the name of the scoring rules
  (``lb1``, ``lb2``: :data:`icrsumo.scoring.SCORINGS`);
* then one line per stored episode, sorted by its key (agent, route_id, family, k, seed),
  strings by code point and integers by value:
  ``[AGENT,ROUTE_ID,FAMILY,K,SEED,"log",HEX]`` with HEX the SHA-256 (64 lowercase hex digits)
  of the UTF-8 bytes of the episode's stored log, the uncompressed JSON text
  (:meth:`icrsumo.results.store.ResultStore.log`; a crashed episode's log up to the crash holds
  its termination ``agent_error`` and message); an episode stored without a log (a crashed one)
  gives ``[AGENT,ROUTE_ID,FAMILY,K,SEED,"no-log",HEX]`` with HEX the SHA-256 of the UTF-8 bytes
  of ``json.dumps([STATUS,MESSAGE], ensure_ascii=True, separators=(",", ":"))`` (a missing
  message is ``""``);
* the digest is ``"sha256:"`` + the SHA-256 (lowercase hex) of all the lines' bytes.

The episode lines cover every row of the store: the episodes of the report and those stored
beside them. Nothing else enters (no scores, which the log and the scoring determine; no
worker count, backend, insertion order, timing or path), so the same episodes give the same
digest wherever they were run.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from icrsumo.core.errors import InputError, short
from icrsumo.results.store import ResultStore

#: the first element of the header line, and the format's version
DIGEST_FORMAT = "icrsumo-digest"
DIGEST_VERSION = 1

#: a digest as written (``sha256:`` + 64 lowercase hex digits)
DIGEST_RE = re.compile(r"sha256:[0-9a-f]{64}")

#: a digest as a user may give it: with or without ``sha256:``, hex in either case
_GIVEN_RE = re.compile(r"(?:sha256:)?([0-9a-fA-F]{64})")

#: an episode's key in the store: (agent, route_id, family, k, seed)
Key = tuple[str, str, str, int, int]


@dataclass(frozen=True, order=True)
class EpisodeHash:
    """One stored episode's part of the digest: its ``key``, ``kind`` ("log": ``sha256`` is of
    its stored log; "no-log": of its status and message) and ``sha256`` (64 hex digits)."""

    key: Key
    kind: str
    sha256: str


def _json(value: object) -> str:
    return json.dumps(value, ensure_ascii=True, separators=(",", ":"))


def episode_hash(key: Key, status: str, message: str | None, log_text: str | None) -> EpisodeHash:
    """The digest's entry of one stored episode (pure): the SHA-256 of its log's JSON text, or,
    stored without a log, of ``[status, message]``."""
    if log_text is not None:
        return EpisodeHash(key, "log", hashlib.sha256(log_text.encode("utf-8")).hexdigest())
    text = _json([status, message or ""])
    return EpisodeHash(key, "no-log", hashlib.sha256(text.encode("utf-8")).hexdigest())


def digest_lines(episodes: Iterable[EpisodeHash], scoring: str) -> list[bytes]:
    """The lines the digest hashes (pure; each ends with ``\\n``): the header naming the format
    and ``scoring``, then one line per episode sorted by key (see the module's docstring)."""
    lines = [_json([DIGEST_FORMAT, DIGEST_VERSION, scoring])]
    lines += [_json([*e.key, e.kind, e.sha256]) for e in sorted(episodes)]
    return [(line + "\n").encode("ascii") for line in lines]


def digest_of(episodes: Iterable[EpisodeHash], scoring: str) -> str:
    """``sha256:`` + the SHA-256 of :func:`digest_lines` (pure)."""
    h = hashlib.sha256()
    for line in digest_lines(episodes, scoring):
        h.update(line)
    return "sha256:" + h.hexdigest()


def store_hashes(store: ResultStore) -> list[EpisodeHash]:
    """The digest's entries of every episode in ``store``, sorted by key; an InputError names an
    episode whose key, status or message has a value no icrsumo stores, or whose log is
    damaged (such a store has no digest)."""
    out = []
    for key, status, message, text in store.logs():
        types = (str, str, str, int, int)
        bad = next((i for i, (v, t) in enumerate(zip(key, types))
                    if not isinstance(v, t) or isinstance(v, bool)), None)
        if bad is None and (not isinstance(status, str) or not isinstance(message, (str, type(None)))):
            bad = 5
        if bad is not None:
            what = ("agent", "route_id", "family", "k", "seed", "status or message")[bad]
            raise InputError(store.path, f"episode {shown_key(key)}", f"its {what} holds a value no icrsumo "
                             "stores", "the store is damaged: move it away and rerun the evaluation")
        out.append(episode_hash(key, status, message, text))
    return sorted(out)


def run_digest(store: ResultStore | str | Path, scoring: str) -> str:
    """The digest of every episode in a results store (a :class:`ResultStore` or the path of
    one, which must exist) under the scoring rules named ``scoring``."""
    if isinstance(store, ResultStore):
        return digest_of(store_hashes(store), scoring)
    path = Path(store)
    if not path.is_file():
        raise InputError(path, "", "no results store here", "give the results.sqlite of an evaluation folder")
    with ResultStore(path, readonly=True) as opened:
        return digest_of(store_hashes(opened), scoring)


def parse_digest(text: str) -> str | None:
    """``text`` as a digest (``sha256:`` + 64 lowercase hex digits) when it is one: with or
    without the ``sha256:`` prefix, hex digits in either case; None otherwise."""
    m = _GIVEN_RE.fullmatch(text.strip()) if isinstance(text, str) else None
    return f"sha256:{m.group(1).lower()}" if m else None


def shown_digest(value: object) -> str:
    """``value`` when it is a well-formed digest, else ``none``: the only text a digest line
    prints (hex digits, never text from a file)."""
    return value if isinstance(value, str) and DIGEST_RE.fullmatch(value) else "none"


def shown_key(key: Sequence[object]) -> str:
    """An episode's key as one printable line: ``agent/route/family/k/seed``, a name with
    control characters or other unprintable ones shown escaped."""
    parts = [p if not isinstance(p, str) or p.isprintable() else repr(p)[1:-1] for p in key]
    text = "/".join(short(p, 40) if not isinstance(p, (str, int)) else str(p) for p in parts)
    return text if len(text) <= 160 else f"{text[:100]}...{text[-40:]}"


# ------------------------------------------------------------------------ folders
@dataclass(frozen=True)
class FolderDigest:
    """The digest of an evaluation folder, computed from its store (``OUT/results.sqlite``)
    under its configuration's scoring. ``suite``: the configuration's suite (a bundled name, or
    the file or folder name of a suite given as a path); ``episodes``: the store's episodes,
    hashed; ``summary``: what ``OUT/summary.json`` says of it, in words ("" when it agrees)."""

    out: Path
    digest: str
    scoring: str
    suite: str
    episodes: tuple[EpisodeHash, ...]
    summary: str = ""

    @property
    def summary_agrees(self) -> bool:
        return not self.summary


def _suite_id(suite: str) -> str:
    """A suite as two machines name it alike: a bundled suite's name, else the last part of the
    path it was given as."""
    from icrsumo.core.resources import bundled_suites

    return suite if suite in bundled_suites() else (Path(suite).name or suite)


def _check_summary(out: Path, hashes: Sequence[EpisodeHash], digest: str, scoring: str) -> str:
    """What ``OUT/summary.json``'s digest says against the store's: "" when it agrees, else one
    line (no summary, no digest in it, another digest)."""
    from icrsumo.core.fsio import read_json
    from icrsumo.scoring import SCORINGS

    path = out / "summary.json"
    if not path.is_file():
        return f"{path} is missing (icrsumo report {out} writes it)"
    try:
        doc = read_json(path, "evaluation summary")
    except InputError as err:
        return f"{path} cannot be read ({err.problem})"
    stored = doc.get("digest") if isinstance(doc, dict) else None
    if stored is None:
        return f"{path} holds no digest (written by an earlier icrsumo; icrsumo report {out} adds it)"
    if shown_digest(stored) == "none":
        return f"{path}: digest is not a digest (icrsumo report {out} rewrites it)"
    rescored = doc.get("scoring")
    if rescored != scoring and isinstance(rescored, str) and rescored in SCORINGS:
        # a report rescored by other rules (icrsumo report OUT --scoring NAME): a digest of those rules
        if digest_of(hashes, rescored) == stored:
            return ""
        return (f"{path}: digest {stored} (of the scoring {rescored} it was rescored by) is not the "
                f"store's: the store changed after it was written (icrsumo report {out} rewrites it)")
    if stored != digest:
        return (f"{path}: digest {stored} is not the store's: the store changed after it was written, "
                f"or the file was edited (icrsumo report {out} rewrites it)")
    return ""


def folder_digest(out: str | Path) -> FolderDigest:
    """The digest of the evaluation folder ``out`` from its store, never taken from
    ``summary.json`` (whose digest is checked against it: :attr:`FolderDigest.summary`). The
    store is read as ``icrsumo report`` reads it; an InputError names a folder that is no
    evaluation folder, a configuration without a scoring, and a damaged store."""
    from icrsumo.core.errors import expect
    from icrsumo.scoring import SCORINGS, scoring_names

    from .plan import read_config

    out = Path(out)
    cfg = read_config(out)
    cfg_path = out / "config.json"
    scoring = cfg.get("scoring")
    if scoring is None:
        raise InputError(cfg_path, "scoring", "its episodes were scored before icrsumo scored by the "
                         "leaderboard's own rules, so the folder has no digest",
                         "run them again into another out folder")
    expect(scoring, str, cfg_path, "scoring", "scoring", "restore it from a copy")
    if scoring not in SCORINGS:
        raise InputError(cfg_path, "scoring", f"unknown scoring {short(scoring)}",
                         f"restore it from a copy (known: {', '.join(scoring_names())})")
    with ResultStore(out / "results.sqlite", readonly=True) as store:  # a read-only folder is fine
        hashes = tuple(store_hashes(store))
        digest = digest_of(hashes, scoring)
    note = _check_summary(out, hashes, digest, scoring)
    return FolderDigest(out, digest, scoring, _suite_id(cfg["suite"]), hashes, note)


@dataclass(frozen=True)
class Comparison:
    """Two runs compared: ``same``; ``digest`` (of the folder) and ``other`` (the other
    folder's, or the digest given); ``first_difference``: for two folders that differ, the
    first episode (in key order) stored in one only or stored with another log, in words."""

    same: bool
    digest: str
    other: str
    first_difference: str = ""


def first_difference(a: Sequence[EpisodeHash], b: Sequence[EpisodeHash], name_a: str, name_b: str) -> str:
    """The first episode, in key order, that ``a`` and ``b`` (sorted) do not share, in words
    ("" when they are the same)."""
    ia = {e.key: e for e in a}
    ib = {e.key: e for e in b}
    for key in sorted(ia.keys() | ib.keys()):
        x, y = ia.get(key), ib.get(key)
        if x == y:
            continue
        where = f"episode {shown_key(key)}"
        if y is None:
            return f"{where} is stored in {name_a} only"
        if x is None:
            return f"{where} is stored in {name_b} only"
        if x.kind == y.kind == "log":
            return f"{where}: its stored logs differ"
        if x.kind == y.kind:
            return f"{where}: stored without a log in both, with another status or message"
        with_log, without = (name_b, name_a) if x.kind == "no-log" else (name_a, name_b)
        return f"{where} has a stored log in {with_log}, none in {without} (crashed there)"
    return ""


def compare(out: str | Path, other: str | Path) -> Comparison:
    """Compare the evaluation folder ``out`` with ``other``: a second evaluation folder, or a
    digest (``sha256:HEX`` or 64 hex digits). Two folders of different scorings or suites are
    an InputError (their digests never agree: nothing to compare); so is an ``other`` that is
    neither an existing folder nor a well-formed digest."""
    mine = folder_digest(out)
    given = str(other)
    if not Path(given).exists():
        digest = parse_digest(given)
        if digest is None:
            raise InputError(short(given, 80), "", "is neither an existing evaluation folder nor a digest "
                             "(sha256: and 64 hex digits)", "give a second out folder, or the digest "
                             "a run printed (icrsumo digest OUT prints it)")
        return Comparison(digest == mine.digest, mine.digest, digest)
    theirs = folder_digest(given)
    a, b = Path(out) / "config.json", Path(given) / "config.json"
    if theirs.scoring != mine.scoring:
        raise InputError(b, "scoring", f"is {theirs.scoring}, {a}'s is {mine.scoring}: runs scored by "
                         "different rules never have the same digest, so they are not compared",
                         "compare two folders of one scoring")
    if theirs.suite != mine.suite:
        raise InputError(b, "suite", f"is {short(theirs.suite)}, {a}'s is {short(mine.suite)}: runs of "
                         "different suites are not compared", "compare two folders of one suite")
    same = theirs.digest == mine.digest
    diff = "" if same else first_difference(mine.episodes, theirs.episodes, str(out), given)
    return Comparison(same, mine.digest, theirs.digest, diff)
