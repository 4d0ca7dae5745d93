"""User-facing input errors: one line naming the file, the place and the fix."""

from __future__ import annotations


class InputError(Exception):
    """Bad user input. The CLI prints ``str(err)`` as one line and exits with status 2.

    ``file`` is the offending file (or option), ``place`` where in it (route id, waypoint index,
    line), ``problem`` what is wrong and ``fix`` what the user should do.
    """

    def __init__(self, file: str, place: str, problem: str, fix: str = "") -> None:
        self.file = str(file)
        self.place = place
        self.problem = problem
        self.fix = fix
        super().__init__(self.line())

    def line(self) -> str:
        where = f"{self.file}: {self.place}: " if self.place else f"{self.file}: "
        text = where + self.problem
        if self.fix:
            text += f" (fix: {self.fix})"
        return " ".join(text.split())


def describe(err: BaseException) -> str:
    """``Type: message at file.py:line`` (the innermost frame): how a failure that is stored or
    sent on (a crashed episode, an agent server's answer) names itself in one line."""
    import traceback

    tb = traceback.extract_tb(err.__traceback__)
    where = f" at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno}" if tb else ""
    return f"{type(err).__name__}: {err}{where}"
