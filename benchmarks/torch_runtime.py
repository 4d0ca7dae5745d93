"""The shipped learned agents' float checkpoints with their network run by torch on the CPU
(the inference of icrsumo 0.x before issue 17; the shipped agents run exact checkpoints since
issue 42), for before/after measurements:

    icrsumo evaluate --agent benchmarks/torch_runtime.py:TokenTorch ...

``tools/benchmark.py`` uses them for its ``@torch`` rows and its ``local-2-torch`` ICR run."""

from __future__ import annotations

from icrsumo.learn.agent import CHECKPOINTS, NgramAgent, NgramAugAgent, TokenAgent


class TokenTorch(TokenAgent):
    """``bev-token`` with torch inference."""

    name = "bev-token-torch"
    checkpoint = str(CHECKPOINTS / "bev-token.pt")  # the float checkpoint (the exact .npz runs no torch)

    def __init__(self, device: str = "cpu") -> None:
        super().__init__(device=device, runtime="torch")


class NgramTorch(NgramAgent):
    """``bev-ngram`` with torch inference."""

    name = "bev-ngram-torch"
    checkpoint = str(CHECKPOINTS / "bev-ngram.pt")  # the float checkpoint (the exact .npz runs no torch)

    def __init__(self, device: str = "cpu") -> None:
        super().__init__(device=device, runtime="torch")


class NgramAugTorch(NgramAugAgent):
    """``bev-ngram-aug`` with torch inference."""

    name = "bev-ngram-aug-torch"
    checkpoint = str(CHECKPOINTS / "bev-ngram-aug.pt")  # the float checkpoint (the exact .npz runs no torch)

    def __init__(self, device: str = "cpu") -> None:
        super().__init__(device=device, runtime="torch")


#: agent name -> its class with torch inference
TORCH = {c.name.removesuffix("-torch"): c for c in (TokenTorch, NgramTorch, NgramAugTorch)}


def spec_of(name: str) -> str:
    """The ``--agent`` spec (``FILE:Class``) of agent ``name`` with torch inference."""
    return f"{__file__}:{TORCH[name].__name__}"
