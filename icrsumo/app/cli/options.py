"""What the subcommands share: how the command line names the library's fields (its errors name
fields: :class:`icrsumo.core.errors.Field`) and the options several subcommands take."""

from __future__ import annotations

import argparse
import functools

from icrsumo.core.defaults import BLOCK_POLICIES
from icrsumo.core.errors import Field, InputError, check_key_env
from icrsumo.core.resources import bundled_suites
from icrsumo.world.traffic import TRAFFIC_LEVELS

#: how the command line names the library's fields: the fields whose option is not ``--FIELD``
#: (``_`` written ``-``); ``"COMMAND FIELD"`` for one command's own
OPTIONS = {"agents": "--agent", "families": "--family", "guards": "--guard",
           "replace_agents": "--replace-agent", "generate families": "--families",
           "check-agent max_decisions": "--decisions", "run-episode instruction_set": "--instructions"}


def option(command: str, field: str) -> str:
    """The option of ``command`` that gives the library's ``field``."""
    return OPTIONS.get(f"{command} {field}") or OPTIONS.get(field) or "--" + field.replace("_", "-")


def names(command: str) -> functools.partial[str]:
    """How ``command``'s errors name fields (:meth:`InputError.line`): by its options."""
    return functools.partial(option, command)


@functools.cache
def suites() -> str:
    """The bundled suites' names, for help texts."""
    return ", ".join(bundled_suites())


def add_traffic(p: argparse.ArgumentParser) -> None:
    """Add ``--traffic LEVEL`` (default normal)."""
    p.add_argument("--traffic", choices=list(TRAFFIC_LEVELS), default="normal")


def add_on_block(p: argparse.ArgumentParser) -> None:
    """Add ``--on-block keep|navigator``: what an instruction a --guard blocks leaves the agent."""
    p.add_argument("--on-block", choices=list(BLOCK_POLICIES), default=BLOCK_POLICIES[0],
                   help="what an instruction a --guard blocks leaves the agent: keep, what it was shown "
                   "before (default); navigator, the navigation plan's instruction for that stretch in "
                   "the route's baseline words, in rows AGENT+guard:NAME+navigator; part of the out "
                   "folder's configuration (docs/guards.md)")


def add_llm_options(p: argparse.ArgumentParser) -> None:
    """Add ``--llm-key-env VAR`` and ``--llm-image``, the options of llm:MODEL@URL agents."""
    p.add_argument("--llm-key-env", metavar="VAR",
                   help="for llm:MODEL@URL agents: the environment variable holding the server's API key "
                   "(the key itself is never given on the command line)")
    p.add_argument("--llm-image", action="store_true",
                   help="for llm:MODEL@URL agents: send the BEV raster as a PNG image part too "
                   "(vision-language models)")


def port(text: str) -> int:
    """A TCP port, 0..65535 (argparse type)."""
    try:
        number = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {text!r}") from None
    if not 0 <= number <= 65535:
        raise argparse.ArgumentTypeError(f"{number} is out of range (use 0 to 65535; 0: any free port)")
    return number


def split_list(items: list[str] | None, option: str = "") -> tuple[str, ...]:
    """The comma-separated values of a repeatable option; an InputError when it was given but
    names nothing (``--family ""``)."""
    values = tuple(x.strip() for item in items or [] for x in item.split(",") if x.strip())
    if items is not None and not values and option:
        raise InputError(option, "", "is empty", f"give a value, or leave {option} out for the default")
    return values


def agent_specs(args: argparse.Namespace) -> tuple[str, ...]:
    """The ``--agent`` specs, with ``--llm-key-env`` and ``--llm-image`` applied to the llm ones."""
    from icrsumo.agents.registry import LLM_PREFIX

    specs = split_list(args.agent, "--agent")
    if (args.llm_key_env or args.llm_image) and not any(s.startswith(LLM_PREFIX) for s in specs):
        flag = "--llm-key-env" if args.llm_key_env else "--llm-image"
        raise InputError(flag, "", "applies to llm:MODEL@URL agents only, and none is given",
                         f"add --agent llm:MODEL@http://HOST:PORT/v1, or leave {flag} out")
    from icrsumo.agents.llm import with_options

    if args.llm_key_env:
        check_key_env(args.llm_key_env, Field("llm_key_env"), args.llm_key_env)

    return tuple(with_options(s, args.llm_key_env, args.llm_image) for s in specs)
