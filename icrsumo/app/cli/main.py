"""The ``icrsumo`` entry point: the parser of :data:`icrsumo.app.cli.SUBCOMMANDS`, the ``--out``
check, and every failure as one line on stderr (no traceback unless ``--debug``)."""

from __future__ import annotations

import argparse
import errno
import signal
import sys
import threading
from pathlib import Path

from icrsumo.core.errors import InputError, naming_fields, visible

from . import SUBCOMMANDS, registry
from .options import names

#: subcommands whose --out is a folder they write (checked before they start)
_WRITES_OUT = ("convert-routes", "generate", "evaluate", "attack", "collect", "train")


def build_parser() -> argparse.ArgumentParser:
    """The ``icrsumo`` parser: one subparser per subcommand (:data:`icrsumo.app.cli.SUBCOMMANDS`),
    each running its module's ``run``; ``--debug`` before or after the subcommand."""
    return registry.build_parser(SUBCOMMANDS)


def _stop_on_signals() -> dict:
    """SIGTERM and SIGHUP stop a command as Ctrl-C does (:class:`icrsumo.core.errors.Stopped`:
    workers stopped, finished episodes stored, exit 128 + signal); the previous handlers."""
    from icrsumo.core.errors import raise_stopped

    old = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGHUP):
            if signal.getsignal(sig) is signal.SIG_DFL:  # not one the caller (or nohup) set
                old[sig] = signal.signal(sig, raise_stopped)
    return old


def _check_out(args: argparse.Namespace) -> None:
    """A subcommand that writes ``--out`` gets a folder it can write (InputError otherwise)."""
    if args.command in _WRITES_OUT:
        from icrsumo.core.fsio import check_out_dir

        if not str(args.out).strip():
            raise InputError("--out", "", "is empty", "give a folder (new or existing)")
        check_out_dir(Path(args.out))


def _stopped(err: KeyboardInterrupt) -> int:
    """Ctrl-C, or SIGTERM / SIGHUP (:class:`icrsumo.core.errors.Stopped`): one line; 128 + signal."""
    signum = getattr(err, "signum", signal.SIGINT)
    what = "interrupted" if signum == signal.SIGINT else f"stopped by {signal.Signals(signum).name}"
    print(f"icrsumo: {what} (every finished episode is stored; run the same command to resume)",
          file=sys.stderr)
    return 128 + int(signum)


def _os_error(err: OSError, args: argparse.Namespace) -> int:
    """A file the command reads or writes, named by the system: one line; exit status 2."""
    if err.errno in (errno.ENOSPC, errno.EDQUOT):  # the disk, not the path, is the problem
        where = err.filename or getattr(args, "out", None) or "(a file)"
        print(f"icrsumo: error: {where}: no space left on the device (fix: free space on that disk and "
              f"run the same command again: what was stored so far is kept and the run resumes)",
              file=sys.stderr)
        return 2
    # os.replace names its source (our temporary file) first and the destination second
    where = err.filename2 or err.filename or "(a file)"
    print(f"icrsumo: error: {visible(str(where))}: {err.strerror or err} (fix: check the path: a folder "
          f"where a file belongs, or the reverse, or its permissions)", file=sys.stderr)
    return 2


def _unexpected(err: Exception) -> int:
    """The last resort: any other failure, still one line; exit status 2."""
    from icrsumo.core.errors import describe

    print(f"icrsumo: error: {visible(' '.join(describe(err).split()))} (fix: check the files and "
          f"options named in the command; rerun with --debug for the traceback and report it if the "
          f"input is right)", file=sys.stderr)
    return 2


def main(argv: list[str] | None = None) -> int:
    """Entry point. Bad input gives one line on stderr and exit status 2; so does any other
    failure that reaches this point (a last resort: one line, never a traceback, unless
    ``--debug``)."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as done:  # --help, --version, or a one-line usage error (status 2)
        return int(done.code or 0)
    old = _stop_on_signals()
    try:
        _check_out(args)
        with naming_fields(names(args.command)):  # the library's notes name options here
            return args.func(args)
    except InputError as err:
        if args.debug:
            raise
        print(f"icrsumo: error: {err.line(names(args.command))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as err:  # Ctrl-C, or SIGTERM / SIGHUP (errors.Stopped)
        return _stopped(err)
    except OSError as err:
        if args.debug:
            raise
        return _os_error(err, args)
    except Exception as err:
        if args.debug:
            raise
        return _unexpected(err)
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
