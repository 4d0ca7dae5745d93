"""The exact checkpoint file: ``NAME.npz`` (numpy's zip of ``.npy`` arrays, read with
``allow_pickle=False``: loading runs no code from the file) holding the integer graph of
:mod:`icrsumo.learn.exact.graph` and, in the array ``__doc__`` (UTF-8 JSON bytes), the format
name, the model config and the provenance (``meta``).

Reading checks everything the graph relies on: the format, the config, every array's name,
shape and dtype (no missing or extra array), finite constants, and that no product can leave
float32's exact integers (``max|x| * sum|w| + |b| < 2**24`` per output channel). A file that
fails is an :class:`icrsumo.core.errors.InputError` naming it and the array.
"""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from icrsumo.core.errors import InputError
from icrsumo.core.fsio import unreadable, write_atomic

from ..config import ModelConfig, config_dict, config_from_dict, short_repr
from ..labels import ARC_M
from .graph import EXACT_LIMIT, SMAX, TABLE_HALF, UMAX

FORMAT = "icrsumo-exact/1"
SUFFIX = ".npz"
_FIX = "make it again with icrsumo export-exact, or use a shipped agent"
_I8, _I32, _F32, _F64 = np.dtype(np.int8), np.dtype(np.int32), np.dtype(np.float32), np.dtype(np.float64)


@dataclass(frozen=True)
class ExactCheckpoint:
    """An exact checkpoint in memory: ``config``, ``arrays`` (name -> array) and ``meta``."""

    config: ModelConfig
    arrays: dict[str, np.ndarray]
    meta: dict


def _dense(out: dict, name: str, n_in: int, n_out: int, post: str = "m", dtype: np.dtype = _F32) -> None:
    if name not in _FIXED_INPUT:
        out[f"{name}.top"] = ((), _I32)
    out[f"{name}.w"] = ((n_in, n_out), _I8)
    out[f"{name}.b"] = ((n_out,), _I32)
    if post:
        out[f"{name}.{post}"] = ((n_out,), dtype)


def layout(cfg: ModelConfig) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Every array of an exact checkpoint of ``cfg``: name -> (shape, dtype)."""
    w, hid, lang, k = cfg.width, cfg.hidden, cfg.lang, len(ARC_M)
    out: dict[str, tuple[tuple[int, ...], np.dtype]] = {}
    _dense(out, "stem", 7 * 16, w)
    _dense(out, "c2", 9 * w, 2 * w)
    _dense(out, "c3", 18 * w, 4 * w, post="")
    out["c3.k"] = out["c3.inv"] = ((4 * w,), _F64)
    _dense(out, "film", lang, 8 * w, post="k", dtype=_F64)
    _dense(out, "c4", 36 * w, 4 * w)
    _dense(out, "fc", 64 * w, hid)
    _dense(out, "mlp0", hid, hid, post="k")
    out["mlp0.m"] = out["mlp0.wsp"] = out["mlp0.wst"] = ((hid,), _F32)
    out["mlp0.wl"] = ((lang, hid), _I8)
    out["mlp0.kl"] = out["mlp0.bias"] = ((hid,), _F64)
    _dense(out, "mlp1", hid, hid)
    _dense(out, "head", hid, 2 * k + 2, post="d")
    out["arc"] = ((k,), _F32)
    if cfg.encoder in ("ngram", "minilm"):
        n_in = cfg.embed if cfg.encoder == "ngram" else cfg.text_len
        if cfg.encoder == "ngram":
            out["lang.emb"] = ((cfg.buckets, cfg.embed), _I8)
            out["lang.emb_m"] = ((cfg.embed,), _F32)
        else:
            out["lang.in_m"] = ((cfg.text_len,), _F32)
        _dense(out, "lang.l1", n_in, lang)
        _dense(out, "lang.l2", lang, lang)
    elif cfg.encoder == "token":
        half = lang // 2
        out["lang.emb"] = ((len(cfg.vocab), cfg.embed), _I8)
        for d in ("f", "r"):
            out[f"gru.{d}.wih"] = ((cfg.embed, 3 * half), _I8)
            out[f"gru.{d}.whh"] = ((half, 3 * half), _I8)
            for key in ("kih", "bih", "khh", "bhh"):
                out[f"gru.{d}.{key}"] = ((3 * half,), _F64)
        out["gru.sigmoid"] = out["gru.tanh"] = ((2 * TABLE_HALF + 1,), _F64)
        out["lang.out_m"] = ((lang,), _F32)
    return out


#: products whose input range is fixed: the BEV (0..255), the language input and vector (-127..127)
_FIXED_INPUT = {"stem": UMAX, "lang.l1": SMAX, "film": SMAX}
#: every product that is converted to float32 (the driving network's and the language MLP's)
_PRODUCTS = ("stem", "c2", "c3", "c4", "fc", "mlp0", "mlp1", "head", "lang.l1", "lang.l2")


def bounds(arrays: dict[str, np.ndarray]) -> dict[str, int]:
    """The largest partial sum each product can reach: ``max|x| * sum|w| + |b|`` over output
    channels (exact int64; ``max|x|`` is the input's top); below 2**24 the float32 product is
    exact in any order."""
    out = {}
    for name in _PRODUCTS:
        if f"{name}.w" in arrays:
            top = _FIXED_INPUT.get(name) or int(arrays[f"{name}.top"])
            w = np.abs(arrays[f"{name}.w"].astype(np.int64)).sum(0)
            out[name] = int((top * w + np.abs(arrays[f"{name}.b"].astype(np.int64))).max())
    return out


def check_arrays(arrays: dict[str, np.ndarray], cfg: ModelConfig, path: Path | str,
                 fix: str = _FIX) -> None:
    """InputError unless ``arrays`` are exactly :func:`layout`'s, finite and within bounds."""
    want = layout(cfg)
    missing = [k for k in want if k not in arrays]
    extra = [k for k in arrays if k not in want]
    if missing or extra:
        parts = ([f"{len(missing)} missing (e.g. {missing[0]})"] if missing else []) + (
            [f"{len(extra)} unexpected (e.g. {short_repr(extra[0])})"] if extra else [])
        raise InputError(path, "arrays", f"do not fit the model config: {', '.join(parts)}", fix)
    for key, (shape, dtype) in want.items():
        a = arrays[key]
        if a.dtype != dtype or a.shape != shape:
            raise InputError(path, key, f"is {a.dtype}{list(a.shape)}, expected {dtype}{list(shape)}", fix)
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            raise InputError(path, key, "holds a non-finite value", fix)
        if key.endswith(".top") and not 1 <= int(a) <= UMAX:
            raise InputError(path, key, f"activation top {int(a)} is not in 1..{UMAX}", fix)
    for name, bound in bounds(arrays).items():
        if bound >= EXACT_LIMIT:
            raise InputError(path, f"{name}.w", f"partial sums can reach {bound} >= 2**24: float32 "
                             "would round them, so the results would depend on the CPU", fix)


def save(ck: ExactCheckpoint, path: Path) -> None:
    """Write ``ck`` atomically (checked first: a checkpoint that would not load is not written)."""
    check_arrays(ck.arrays, ck.config, path)
    doc = {"format": FORMAT, "config": config_dict(ck.config), "meta": ck.meta}
    arrays = {"__doc__": np.frombuffer(json.dumps(doc, sort_keys=True).encode("utf-8"), np.uint8),
              **ck.arrays}
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    write_atomic(Path(path), buf.getvalue())


def load(path: Path | str) -> ExactCheckpoint:
    """Read and check an exact checkpoint (see the module docstring)."""
    path = Path(path)
    if path.is_dir():
        raise InputError(path, "", "is a folder, not an exact checkpoint", f"pass the {SUFFIX} file")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (FileNotFoundError, PermissionError) as err:
        raise unreadable(path, "exact checkpoint", "check the path", err) from None
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, KeyError) as err:
        why = " ".join(str(err).split())[:100]
        raise InputError(path, "", f"not a readable exact checkpoint ({type(err).__name__}: {why})",
                         _FIX) from None
    raw = arrays.pop("__doc__", None)
    if raw is None or raw.dtype != np.uint8 or raw.ndim != 1:
        raise InputError(path, "__doc__", "missing: not an icrsumo exact checkpoint", _FIX)
    try:
        doc = json.loads(raw.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as err:
        raise InputError(path, "__doc__", f"is not JSON ({err})", _FIX) from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        fmt = doc.get("format") if isinstance(doc, dict) else doc
        raise InputError(path, "__doc__.format",
                         f"not an icrsumo exact checkpoint (format {short_repr(fmt)})", _FIX)
    cfg = config_from_dict(doc.get("config"), path, "__doc__.config", _FIX)
    if cfg.encoder not in ("ngram", "token", "minilm"):
        raise InputError(path, "__doc__.config.encoder", f"no exact inference for encoder {cfg.encoder!r}",
                         "use ngram, token or minilm")
    meta = doc.get("meta", {})
    if not isinstance(meta, dict):
        raise InputError(path, "__doc__.meta", "is not an object", _FIX)
    check_arrays(arrays, cfg, path)
    return ExactCheckpoint(config=cfg, arrays=arrays, meta=meta)
