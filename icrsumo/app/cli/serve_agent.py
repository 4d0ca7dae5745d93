"""``icrsumo serve-agent``: an agent served over HTTP for remote:URL.
Its parser (``add``) and its handler (``run``)."""

from __future__ import annotations

import argparse

from .options import port
from .registry import Commands


def add(sub: Commands) -> None:
    """Add the parser of ``icrsumo serve-agent``."""
    sa = sub.add_parser(
        "serve-agent", help="serve an agent over HTTP (protocol icrsumo-agent/1) for remote:URL",
        description="Wrap an agent spec in an HTTP server: one agent instance per episode session, "
        "concurrent act requests batched (through the agent's act_batch hook if it has one). Use it "
        "with icrsumo evaluate --agent remote:http://HOST:PORT.",
    )
    sa.add_argument("spec", help="built-in name, module:Class or path/file.py:Class (not privileged)")
    sa.add_argument("--port", type=port, default=8765, help="TCP port (default 8765; 0: any free port)")
    sa.add_argument("--host", default="127.0.0.1",
                    help="address to bind (default 127.0.0.1; 0.0.0.0 exposes the agent to the network)")
    sa.add_argument("--max-batch", type=int, default=8, help="act requests per batch at most (default 8)")
    sa.add_argument("--device", help="where a learned agent runs: cpu (default), cuda, cuda:N or auto")
    sa.add_argument("--key-env", metavar="VAR",
                    help="require the shared key held by the environment variable VAR on every request "
                    "(clients: remote:http://HOST:PORT?key_env=VAR); advised off 127.0.0.1")
    sa.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``icrsumo serve-agent``; its exit status."""
    from icrsumo.agents.hosting.serve import serve

    serve(args.spec, host=args.host, port=args.port, max_batch=args.max_batch, device=args.device,
          key_env=args.key_env)
    return 0
