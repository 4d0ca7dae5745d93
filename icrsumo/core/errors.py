"""User-facing input errors: one line naming the file, the place and the fix."""

from __future__ import annotations

import contextlib
import re
import sys
import unicodedata
from collections.abc import Callable, Iterator
from dataclasses import dataclass

#: the character that brackets a mention of a field in an error's text (``str(Field(name))``)
_MARK = "\x1f"
_MENTION = re.compile(f"{_MARK}([A-Za-z_][A-Za-z0-9_]*){_MARK}")


@dataclass(frozen=True)
class Field:
    """A field of the options a call takes, by its Python name (``suite``, ``rollout_route``):
    what an :class:`InputError` is about (its first argument), or a mention of one in its text
    (``f"use another {Field('out')} folder"``). The error names it in its reader's words: the
    Python API by the keyword (``out``), the CLI by its option (``--out``,
    ``icrsumo.app.cli.options`` maps them)."""

    name: str

    def __str__(self) -> str:
        return f"{_MARK}{self.name}{_MARK}"


def _as_named(name: str) -> str:
    return name


class InputError(Exception):
    """Bad user input. The CLI prints :meth:`line` as one line and exits with status 2.

    ``file`` is the offending file, or a :class:`Field` (then also ``field``: its name);
    ``place`` where in it (route id, waypoint index, line, the value given), ``problem`` what
    is wrong and ``fix`` what the user should do. ``str(err)`` names fields as the Python API
    does (the keyword); the texts may mention fields (``str(Field(name))``).
    """

    def __init__(self, file: object, place: str, problem: str, fix: str = "") -> None:
        self.field = file.name if isinstance(file, Field) else None
        self.file = str(file)
        self.place = place
        self.problem = problem
        self.fix = fix
        super().__init__(self.line())

    def __reduce__(self) -> tuple:  # pickled whole (a worker's error reaches its parent as it was)
        file = Field(self.field) if self.field is not None else self.file
        return type(self), (file, self.place, self.problem, self.fix)

    @classmethod
    def of_line(cls, line: str) -> InputError:
        """The error whose :meth:`line` is ``line`` (one already formatted, e.g. by a worker)."""
        return cls(line, "", "")

    def line(self, names: Callable[[str], str] = _as_named) -> str:
        """The one line: ``file: place: problem (fix: fix)``, every field named by
        ``names(field)`` (default: its Python name; the CLI passes its options')."""
        if not self.problem:
            return _MENTION.sub(lambda m: names(m.group(1)), " ".join(self.file.split()))
        where = f"{self.file}: {self.place}: " if self.place else f"{self.file}: "
        text = where + self.problem
        if self.fix:
            text += f" (fix: {self.fix})"
        text = _MENTION.sub(lambda m: names(m.group(1)), text)
        return visible(display_url(" ".join(text.split())))


#: how notes name fields now: the Python API by keyword; the CLI installs its options' names
_NOTE_NAMES: list[Callable[[str], str]] = [_as_named]


def note(text: str, kind: str = "note") -> None:
    """Print ``icrsumo: KIND: text`` as one line on stderr, every field mentioned in ``text``
    (``str(Field(name))``) named in the reader's words: by keyword in Python, by option under
    the command line (:func:`naming_fields`)."""
    line = " ".join(_MENTION.sub(lambda m: _NOTE_NAMES[-1](m.group(1)), text).split())
    print(f"icrsumo: {kind}: {visible(display_url(line))}", file=sys.stderr, flush=True)


def note_names() -> Callable[[str], str]:
    """How notes name fields now (for an error quoted in a note: ``err.line(note_names())``)."""
    return _NOTE_NAMES[-1]


@contextlib.contextmanager
def naming_fields(names: Callable[[str], str]) -> Iterator[None]:
    """While inside, :func:`note` names fields by ``names(field)`` (the CLI: its options)."""
    _NOTE_NAMES.append(names)
    try:
        yield
    finally:
        _NOTE_NAMES.pop()


#: the password of a URL's user info: ``scheme://user:PASSWORD@`` (up to the authority's last @)
_URL_PASSWORD = re.compile(r"(?P<head>\b[A-Za-z][A-Za-z0-9+.-]*://[^/\s:@?#]*):[^/\s?#]*@")


def display_url(text: str) -> str:
    """``text`` with the password of every URL in it replaced by ``***``
    (``http://user:***@host/v1``): how a URL (or a spec or message holding one) is shown or
    stored; the password itself only ever goes to the URL's own server."""
    return _URL_PASSWORD.sub(r"\g<head>:***@", text)


#: characters a terminal acts on or hides, besides the C0 / C1 controls: bidirectional overrides
#: and isolates, which reorder what is shown
_BIDI = frozenset("\u061c\u200e\u200f\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")


def _hidden(c: str) -> bool:
    return unicodedata.category(c) in ("Cc", "Cs", "Zl", "Zp") or c in _BIDI


def visible(text: str) -> str:
    """``text`` safe for a terminal: every control character (escape sequences such as
    ``\\x1b[2J`` or a clipboard write ``\\x1b]52;...``, newlines, bidirectional overrides, lone
    surrogates) written out as Python writes it in a ``repr`` (``\\x1b``, ``\\n``, ``\\u202e``),
    the rest as it is. How names, instructions and other text from users or servers reach
    messages and progress lines."""
    if not any(_hidden(c) for c in text):
        return text
    return "".join(repr(c)[1:-1] if _hidden(c) else c for c in text)


def short(value: object, limit: int = 40) -> str:
    """``repr(value)``, cut in the middle when longer than ``limit`` characters (a 400-digit
    number or a megabyte-long id stays one short line)."""
    text = value if isinstance(value, str) else repr(value)
    text = repr(text) if isinstance(value, str) else text
    if len(text) <= limit:
        return text
    n = len(value) if isinstance(value, str) else len(text)
    return f"{text[:limit * 2 // 3]}...{text[-(limit // 3):]} ({n} characters)"


def describe(err: BaseException) -> str:
    """``Type: message at file.py:line`` (the innermost frame): how a failure that is stored or
    sent on (a crashed episode, an agent server's answer) names itself in one line."""
    import traceback

    tb = traceback.extract_tb(err.__traceback__)
    where = f" at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno}" if tb else ""
    return f"{type(err).__name__}: {err}{where}"


#: how messages name the JSON types
KIND_NAMES: dict[type, str] = {int: "an integer", float: "a number", str: "a string", list: "a list",
                               dict: "an object", bool: "true or false"}


def is_kind(value: object, kind: type | tuple[type, ...]) -> bool:
    """Whether ``value`` is of ``kind`` (a bool is not an int or a float here)."""
    kinds = kind if isinstance(kind, tuple) else (kind,)
    return isinstance(value, kinds) and not (isinstance(value, bool) and bool not in kinds)


def type_problem(value: object, kind: type | tuple[type, ...], what: str) -> str:
    """``what`` must be <kind>, not <the type of value>: how a value of the wrong type is named."""
    kinds = kind if isinstance(kind, tuple) else (kind,)
    want = " or ".join(KIND_NAMES.get(k, k.__name__) for k in kinds)
    got = "null" if value is None else type(value).__name__
    return f"{what} must be {want}, not {got}"


def expect(value: object, kind: type | tuple[type, ...], file: object, place: str, what: str,
           fix: str = "") -> object:
    """``value`` if it is of ``kind`` (a bool is not an int or a float here), else an
    InputError: ``file``: ``place``: ``what`` must be <kind>, not <its type> (fix: ``fix``)."""
    if not is_kind(value, kind):
        raise InputError(file, place, type_problem(value, kind, what), fix)
    return value


class Interrupted(KeyboardInterrupt):
    """Ctrl-C from the user while an evaluation runs agents in its own process: unlike a
    ``KeyboardInterrupt`` (or ``SystemExit``) raised by agent code, which is an agent crash
    like any other, it stops the evaluation."""


def raise_interrupted(signum: int, frame: object) -> None:
    """A SIGINT handler that raises :class:`Interrupted`."""
    raise Interrupted()


class Stopped(Interrupted):
    """SIGTERM or SIGHUP (``kill PID``, a job scheduler, a parent's ``terminate()``, a closed
    terminal): the run stops as on Ctrl-C (workers stopped, every finished episode stored) and
    the command exits with 128 + ``signum``."""

    def __init__(self, signum: int) -> None:
        super().__init__(f"stopped by signal {signum}")
        self.signum = signum


def raise_stopped(signum: int, frame: object) -> None:
    """A SIGTERM / SIGHUP handler that raises :class:`Stopped`."""
    raise Stopped(signum)


#: the largest seed: seeds are stored as SQLite integers and feed numpy's generators
MAX_SEED = 2**63 - 1


def check_seed(seed: object, where: object = Field("seed")) -> int:
    """``seed`` when it is a whole number in 0 .. :data:`MAX_SEED`, else an InputError naming
    ``where`` (the field ``seed``, or a file's place)."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise InputError(where, short(seed), "out of range", "use a whole number from 0 to 2**63 - 1")
    return seed


def check_key_text(key: str, var: str, option: Field, value: str) -> str:
    """``key`` (read from the environment variable ``var``) when every character of it is
    printable ASCII, which is what an HTTP header carries; an InputError naming the field ``option``,
    its ``value`` and ``var`` otherwise (the position of the first bad character, never the
    key)."""
    bad = next((i for i, c in enumerate(key) if not (c.isascii() and c.isprintable())), None)
    if bad is not None:
        raise InputError(option, value, f"the key in {var} holds a character that is not printable ASCII "
                         f"(character {bad + 1} of {len(key)}), which an HTTP header cannot carry",
                         f"put a key of printable ASCII characters in {var} (the same on both sides), e.g. "
                         "the output of: openssl rand -hex 32")
    return key


def check_key_env(name: object, option: Field, value: str) -> str:
    """``name`` when it is an environment variable's name (the variable that holds an API or
    shared key: the key itself never goes on a command line); an InputError naming the field ``option``
    (and its ``value``) otherwise."""
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
        raise InputError(option, value, f"key_env={name!r} is not a variable name",
                         "name the variable that holds the key, e.g. key_env=MY_KEY")
    return name
