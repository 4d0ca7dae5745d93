"""The float checkpoints of the learned agents (``.pt``, :mod:`icrsumo.learn.nets`): the inference
checkpoint :func:`export` writes and the training state ``OUT/last.pt``.

Checkpoints are plain dicts of tensors, strings and numbers, read with
``torch.load(..., weights_only=True)``; a file that is missing, empty, truncated, not a torch
file, refused by that safe loader, or whose weights do not fit its model config is an
:class:`icrsumo.core.errors.InputError` naming the file (:func:`load`, :func:`read_checkpoint`).
"""

from __future__ import annotations

import pickle
import re
from pathlib import Path
from typing import TYPE_CHECKING

import torch

from icrsumo.core.errors import InputError, expect
from icrsumo.core.fsio import unreadable

from ..config import _CHECKPOINT_FIX, ModelConfig, config_from_dict
from ..config import config_dict as _cfg_dict
from ..config import short_repr as _short
from .models import BevLanguageNet

if TYPE_CHECKING:
    from .trainer import Trainer

CHECKPOINT_FORMAT = "icrsumo-agent/1"
#: format of the training state OUT/last.pt
STATE_FORMAT = CHECKPOINT_FORMAT + "+train"


def error_line(err: BaseException) -> str:
    """The first sentence of an exception's message, without terminal escapes, for one line."""
    text = re.sub(r"\x1b\[[0-9;]*m", "", str(err)).strip()
    text = (text.splitlines() or [""])[0].split(". ")[0].strip()
    text = text[:160] + ("..." if len(text) > 160 else "")
    return f"{type(err).__name__}: {text}" if text else type(err).__name__


def check_weights(weights: object, cfg: ModelConfig, path: Path | str = "checkpoint", place: str = "model",
                  fix: str = _CHECKPOINT_FIX) -> dict:
    """``weights`` if they are a state dict of :class:`BevLanguageNet` with ``cfg`` (the same
    names, shapes and floating-point tensors); an InputError naming ``path`` otherwise. The
    expected shapes come from a model on the ``meta`` device: nothing is allocated."""
    weights = expect(weights, dict, path, place, "the weights", fix)
    with torch.device("meta"):
        want = {k: tuple(v.shape) for k, v in BevLanguageNet(cfg).state_dict().items()}
    missing = [k for k in want if k not in weights]
    extra = [str(k) for k in weights if k not in want]
    if missing or extra:
        parts = ([f"{len(missing)} missing (e.g. {missing[0]})"] if missing else []) + (
            [f"{len(extra)} unexpected (e.g. {extra[0]})"] if extra else [])
        raise InputError(path, place, f"weights do not fit the model config: {', '.join(parts)}", fix)
    for k, shape in want.items():
        t = weights[k]
        if not isinstance(t, torch.Tensor) or not t.is_floating_point():
            kind = f"tensor of {t.dtype}" if isinstance(t, torch.Tensor) else type(t).__name__
            raise InputError(path, f"{place}.{k}", f"is a {kind}, not a floating-point tensor", fix)
        if tuple(t.shape) != shape:
            raise InputError(path, f"{place}.{k}", f"shape {tuple(t.shape)} does not fit the model "
                             f"config's {shape}", fix)
    return weights


def save(obj: dict, path: Path) -> None:
    """Write ``obj`` with torch.save atomically (temporary file, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    torch.save(obj, tmp)
    tmp.replace(path)


def load(path: Path, what: str = "checkpoint", fix: str = _CHECKPOINT_FIX) -> dict:
    """Read a checkpoint dict with ``weights_only=True`` (no code runs from the file). A file
    that is missing, empty, truncated, not a torch file, refused by the safe loader or not a
    dict is an InputError naming it (``what`` names the file in the message)."""
    path = Path(path)
    if path.is_dir():
        raise InputError(path, "", f"is a folder, not a file ({what})", "pass the .pt file")
    try:
        if path.stat().st_size == 0:
            raise InputError(path, "", f"{what} is empty (0 bytes)", fix)
        obj = torch.load(path, map_location="cpu", weights_only=True)
    except InputError:
        raise
    except (FileNotFoundError, PermissionError) as err:
        raise unreadable(path, what, "check the path", err) from None
    except pickle.UnpicklingError as err:
        if "Weights only load failed" not in str(err):
            raise InputError(path, "", f"{what} is damaged, not a torch file ({error_line(err)})",
                             fix) from None
        m = re.search(r"GLOBAL ([\w.]+)", str(err))
        held = f" ({m.group(1)})" if m else ""
        raise InputError(path, "", f"{what} refused by torch.load(weights_only=True): it holds a pickled "
                         f"Python object{held}, not only tensors, numbers and strings", "never load an "
                         "untrusted pickle; " + fix) from None
    except EOFError:
        raise InputError(path, "", f"{what} is truncated", fix) from None
    except MemoryError:
        raise
    except Exception as err:  # torch's reader: truncated zip archive, not a torch file, ...
        raise InputError(path, "", f"{what} is truncated or not a torch file ({error_line(err)})",
                         fix) from None
    if not isinstance(obj, dict):
        raise InputError(path, "", f"{what} holds a {type(obj).__name__}, not an icrsumo checkpoint", fix)
    return obj


def read_checkpoint(path: Path) -> tuple[dict, ModelConfig]:
    """An inference checkpoint (:func:`export`) and its model config, checked: its format, its
    config and that its weights fit that config; problems are InputErrors naming ``path``."""
    ck = load(path, "agent checkpoint")
    fmt = ck.get("format")
    if fmt != CHECKPOINT_FORMAT:
        hint = " (a training state: use the model.pt beside it)" if fmt == STATE_FORMAT else ""
        raise InputError(path, "format", f"not an icrsumo agent checkpoint (format {_short(fmt)}){hint}",
                         _CHECKPOINT_FIX)
    cfg = config_from_dict(ck.get("config"), path)
    check_weights(ck.get("model"), cfg, path)
    return ck, cfg


def export(trainer: Trainer, path: Path, meta: dict) -> None:
    """The inference checkpoint: format, config, float32 weights and ``meta`` (data, steps)."""
    weights = {k: v.detach().to("cpu", torch.float32) if v.is_floating_point() else v.detach().cpu()
               for k, v in trainer.model.state_dict().items()}
    save({"format": CHECKPOINT_FORMAT, "config": _cfg_dict(trainer.cfg), "model": weights,
          "meta": meta}, path)
