"""``icrsumo list``: what exists: suites, a suite's routes, agents, guards, families.
Its parser (``add``) and its handler (``run``)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Iterable

from icrsumo.core.defaults import DEFAULT_SUITE
from icrsumo.core.errors import visible
from icrsumo.core.vocab import ALL_FAMILIES, CONTROL_FAMILIES, FAMILIES

from .registry import Commands


def _suites(args: argparse.Namespace) -> None:
    """The bundled suites: name, coordinate frame, file."""
    from icrsumo.core.resources import bundled_suites, suite_coords

    for name, path in bundled_suites().items():
        print(f"{name:16} {suite_coords(name) or 'sumo':6} {path.name}")


def _routes(args: argparse.Namespace) -> None:
    """The routes of ``--suite``: id, town, waypoints."""
    from icrsumo.world.routes import read_routes, suite_file

    routes, _ = read_routes(suite_file(args.suite))
    for r in routes:
        print(f"{r.id:24} {r.town:10} {len(r.waypoints)} waypoints")


def _skipped(kind: str, skipped: Iterable[tuple[str, str, str]]) -> None:
    """A note on stderr for each plugin entry that is not registered, and why."""
    for name, dist, why in skipped:
        print(f"icrsumo: note: the {kind} {name!r} of the plugin {visible(dist)} is not registered: "
              f"{visible(why)}",
              file=sys.stderr)


def _agents(args: argparse.Namespace) -> None:
    """The registered agents, the default marked."""
    from icrsumo.agents.registry import DEFAULT_AGENT, REGISTRY

    for name in REGISTRY:
        mark = " (default)" if name == DEFAULT_AGENT else ""
        print(f"{visible(name):22} {visible(REGISTRY.entry(name).description)}{mark}")
    _skipped("agent", REGISTRY.skipped_plugins)


def _guards(args: argparse.Namespace) -> None:
    """The instruction guards, llm:MODEL@URL included."""
    from icrsumo.guards.registry import GUARDS

    for name in GUARDS:
        print(f"{visible(name):22} {visible(GUARDS.entry(name).description)}")
    print(f"{'llm:MODEL@URL':22} asks a language model whether the instruction conflicts with the plan")
    _skipped("guard", GUARDS.skipped_plugins)


def _families(args: argparse.Namespace) -> None:
    """The families: default, control or delivery, and what each does."""
    from icrsumo.core.vocab import FAMILY_DESCRIPTIONS

    for fam in ALL_FAMILIES:
        kind = "default" if fam in FAMILIES else "control" if fam in CONTROL_FAMILIES else "delivery"
        print(f"{fam.value:12} {kind:8} {FAMILY_DESCRIPTIONS[fam]}")


#: what ``icrsumo list`` lists, in the order of its choices: each one's printer
_LISTS: dict[str, Callable[[argparse.Namespace], None]] = {
    "suites": _suites, "routes": _routes, "agents": _agents, "guards": _guards, "families": _families}


def add(sub: Commands) -> None:
    """Add the parser of ``icrsumo list``."""
    ls = sub.add_parser("list", help="what exists: suites, a suite's routes, agents, guards, families",
                        description="Print the bundled suites (name, coordinate frame, file), the routes of "
                        "a suite (--suite), the registered agents (the default marked), the instruction "
                        "guards or the families.")
    ls.add_argument("what", choices=list(_LISTS))
    ls.add_argument("--suite", default=DEFAULT_SUITE,
                    help=f"the suite whose routes to list (default {DEFAULT_SUITE})")
    ls.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``icrsumo list``; its exit status."""
    _LISTS[args.what](args)
    return 0
