"""How the ``icrsumo`` parser is built from subcommand modules (the mechanism; which modules it
registers, and in what order, is :data:`icrsumo.app.cli.SUBCOMMANDS`)."""

from __future__ import annotations

import argparse
from collections.abc import Iterable
from typing import NoReturn, Protocol

from icrsumo import __version__

#: what ``parser.add_subparsers()`` returns: where each subcommand adds its parser
Commands = argparse._SubParsersAction

_DEBUG_HELP = "show the traceback of an error instead of its one line"


class Subcommand(Protocol):
    """A subcommand's module: its ``add`` adds its parser, whose ``func`` default runs it."""

    def add(self, sub: Commands) -> None: ...


class Parser(argparse.ArgumentParser):
    """argparse with its errors on one line (no usage block), exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (fix: see {self.prog} --help)\n")


def build_parser(subcommands: Iterable[Subcommand]) -> argparse.ArgumentParser:
    """The ``icrsumo`` parser: one subparser per subcommand, in the order given, each running
    its module's handler; ``--debug`` before or after the subcommand."""
    parser = Parser(
        prog="icrsumo",
        description="Instruction-robustness benchmark for language-conditioned driving on SUMO.",
    )
    parser.add_argument("--version", action="version", version=f"icrsumo {__version__}")
    parser.add_argument("--debug", action="store_true", help=_DEBUG_HELP)
    sub = parser.add_subparsers(dest="command", required=True)
    for command in subcommands:
        command.add(sub)
    for command_parser in sub.choices.values():  # --debug also after the subcommand
        command_parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                                    help=_DEBUG_HELP)
    return parser
