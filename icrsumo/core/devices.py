"""Torch device names given on the command line (``cpu``, ``cuda``, ``cuda:N``, ``auto``),
checked before anything runs (torch is imported only to ask for CUDA)."""

from __future__ import annotations

import re

from .errors import Field, InputError

_DEVICE = re.compile(r"(cpu|auto|cuda(:\d+)?)")


def check_device(name: str, option: object = Field("device")) -> str:
    """``name`` when it is a device this machine has (``auto`` always is); an InputError naming
    the field ``option`` otherwise: an unknown name, CUDA without a GPU, or a GPU index out of range."""
    fix = "use cpu, cuda, cuda:N or auto"
    if not isinstance(name, str) or not _DEVICE.fullmatch(name):
        raise InputError(option, str(name), "unknown device", fix)
    if name.startswith("cuda"):
        try:
            import torch
        except ImportError:
            raise InputError(option, name, "CUDA needs torch, which is not installed",
                             "pip install 'icrsumo[train]' (or use cpu)") from None

        count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        index = int(name.partition(":")[2] or 0)
        if index >= count:
            have = f"{count} CUDA device{'s' if count != 1 else ''}" if count else "no CUDA device"
            raise InputError(option, name, f"this machine has {have}", "use cpu or auto")
    return name
