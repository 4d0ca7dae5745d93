"""Progress of an evaluation on stderr (tqdm): episodes stored out of those to run, episodes
per second and the time left. On a terminal a live bar; otherwise (a log file, CI) an update
about every 10 % of the episodes. ``quiet``: nothing."""

from __future__ import annotations

import sys

from tqdm import tqdm


class Progress:
    """Counts stored episodes (:meth:`tick`); a context manager that closes the bar."""

    def __init__(self, total: int, quiet: bool) -> None:
        self.total, self.done = total, 0
        self._bar: tqdm | None = None
        if quiet or total == 0:
            return
        stream = sys.stderr
        tty = bool(getattr(stream, "isatty", lambda: False)())
        self._bar = tqdm(total=total, desc="icrsumo", unit="episode", file=stream, dynamic_ncols=tty,
                         ascii=not tty, leave=True, smoothing=0.1,
                         mininterval=0.1 if tty else 0.0, miniters=None if tty else max(1, total // 10))

    def tick(self) -> None:
        """One more episode stored."""
        self.done += 1
        if self._bar is not None:
            self._bar.update(1)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
