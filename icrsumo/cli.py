"""The ``icrsumo`` command's entry point (the console script and ``python -m icrsumo``): it
re-exports :func:`icrsumo.app.main.main` and :func:`icrsumo.app.main.build_parser`. The command
itself is the application layer, :mod:`icrsumo.app`: one module per subcommand."""

from __future__ import annotations

import sys

from .app.main import build_parser, main

__all__ = ["build_parser", "main"]

if __name__ == "__main__":
    sys.exit(main())
