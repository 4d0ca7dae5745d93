"""The application layer: the ``icrsumo`` command, on top of the library (nothing of the library
imports it; :func:`icrsumo.app.cli.main.main`, the console script, and ``python -m icrsumo`` are
its entry points).

One module per subcommand, each with its parser (``add``) and its handler (``run``);
:mod:`icrsumo.app.cli.options` holds what they share (the table that names the library's fields by
their options in errors), :mod:`icrsumo.app.cli.registry` how the parser is built from the modules
(:data:`SUBCOMMANDS`, below) and :mod:`icrsumo.app.cli.main` the entry point and its error lines."""

from __future__ import annotations

from . import (
    attack,
    check_agent,
    collect,
    convert_routes,
    digest,
    evaluate,
    export_exact,
    generate,
    listing,
    report,
    run_episode,
    serve_agent,
    serve_llm,
    show,
    train,
)

#: the subcommands' modules, in the order ``icrsumo --help`` lists them
SUBCOMMANDS = (convert_routes, generate, run_episode, evaluate, attack, show, listing, report, digest,
               check_agent, serve_agent, serve_llm, collect, train, export_exact)
