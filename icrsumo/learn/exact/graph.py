"""The exact network, defined once: the integer graph of a learned agent, over a pluggable
matrix product (``Engine``).

Every matrix product multiplies integers (activations: 0..255 or -127..127; weights: int8 per
output channel) and adds an integer bias; :func:`icrsumo.learn.exact.quantize.export_exact`
checks that no partial sum of any output channel can reach 2**24 (``max |x| * sum |w| + |b|``),
so a float32 product is exact whatever its summation order. What follows a product is
elementwise IEEE-754 arithmetic in a fixed order: a requantisation is one float32 multiply by a
per-channel constant, round half to even (``numpy.rint``) and a clip; mixed-scale sums (the
FiLM modulation, the MLP's language/speed inputs) are fixed sequences of float32 multiplies and
adds. None of these depends on the CPU.

Layouts: the BEV ``(B, 7, 128, 128)`` uint8 (0/255, read as value/255); convolution
activations are rows ``(B*H*W, C)`` (NHWC), so each convolution is one product of an im2col
matrix (pure data movement) with ``(kh*kw*C_in, C_out)`` weights. The language side (per
distinct text, :func:`language`) is computed in int64 (exact in any order) and gives
:class:`LangState`, the per-text constants of :func:`fuse`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

#: partial sums of a float32 product stay below this (the exporter checks every layer)
EXACT_LIMIT = 1 << 24
#: the driving network's matrix products (an Engine computes them); each but the first reads
#: activations 0..``{name}.top`` (the exporter picks the top, at most UMAX, that keeps the product
#: exact), the first the BEV's 0..255
PRODUCTS = ("stem", "c2", "c3", "c4", "fc", "mlp0", "mlp1", "head")
#: activation range of the unsigned (post-ReLU) activations and of the signed language input
UMAX, SMAX = 255, 127
#: range of the language vector (only ever multiplied in int64, so it can be wide)
LMAX = 32767
#: sigmoid / tanh tables: inputs quantised to 1/TABLE_STEP over [-TABLE_HALF, TABLE_HALF] / TABLE_STEP
TABLE_STEP, TABLE_HALF = 256, 2048
#: the GRU's hidden state is carried in units of 2**-HIDDEN_BITS
HIDDEN_BITS = 14

#: ``mm(x, layer)``: the float32 array of ``x @ W[layer] + b[layer]`` computed exactly (x holds
#: integers, any numeric dtype)
Engine = Callable[[np.ndarray, str], np.ndarray]


@dataclass(frozen=True)
class LangState:
    """Per-text constants of :func:`fuse` (float32): FiLM multiplier ``film_m`` and offset
    ``film_b`` of the third convolution's channels (C3,), the language part of the first MLP
    layer ``mlp_l`` (H,), bias included; ``lang_q`` the (lang,) int64 language vector."""

    film_m: np.ndarray
    film_b: np.ndarray
    mlp_l: np.ndarray
    lang_q: np.ndarray


def requant(acc: np.ndarray, m: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """``clip(rint(acc * m), lo, hi)`` in float32 (one correctly rounded multiply, round half
    to even); ``acc`` float32 holding exact integers, ``m`` (C,) float32 broadcast over rows."""
    y = np.multiply(acc, m, dtype=np.float32)
    np.rint(y, out=y)
    np.clip(y, lo, hi, out=y)
    return y


def patches4(bev: np.ndarray) -> np.ndarray:
    """``(B, C, H, W)`` uint8 -> ``(B*H/4*W/4, C*16)`` non-overlapping 4x4 patches, columns in
    the order (c, kh, kw) of a torch weight ``(C_out, C, 4, 4)`` flattened."""
    b, c, h, w = bev.shape
    return _patch_bytes(patch_words(bev)).reshape(b * (h // 4) * (w // 4), c * 16)


def patch_words(bev: np.ndarray) -> np.ndarray:
    """``(B, C, H, W)`` uint8 -> a view ``(B, H/4, W/4, C, 4)`` uint32 of its 4x4 patches: each
    patch row's 4 bytes as one uint32 (4x fewer elements to move). ``_patch_bytes`` of any
    selection of its patches gives their rows of :func:`patches4`."""
    b, c, h, w = bev.shape
    words = np.ascontiguousarray(bev, dtype=np.uint8).view(np.uint32)      # (B, C, H, W/4)
    return words.reshape(b, c, h // 4, 4, w // 4).transpose(0, 2, 4, 1, 3)  # (B, i, j, c, kh)


def _patch_bytes(words: np.ndarray) -> np.ndarray:
    """Patches ``(..., C, 4)`` uint32 -> their bytes ``(..., C*16)`` uint8, contiguous."""
    return np.ascontiguousarray(words).view(np.uint8).reshape(*words.shape[:-2], words.shape[-2] * 16)


def im2col3s2(rows: np.ndarray, b: int, h: int, w: int) -> np.ndarray:
    """NHWC rows ``(B*H*W, C)`` -> ``(B*H/2*W/2, 9*C)``: the 3x3 windows of a stride-2,
    padding-1 convolution, columns in the order (kh, kw, c)."""
    return windows3s2(rows, b, h, w).reshape(b * (h // 2) * (w // 2), 9 * rows.shape[-1])


def windows3s2(rows: np.ndarray, b: int, h: int, w: int) -> np.ndarray:
    """NHWC rows ``(B*H*W, C)`` (or ``(B, H, W, C)``) -> a read-only view ``(B, H/2, W/2, 3, 3, C)``
    of the zero-padded input: the 3x3 window of each output of a stride-2, padding-1 convolution."""
    c = rows.shape[-1]
    xp = np.zeros((b, h + 2, w + 2, c), dtype=rows.dtype)
    xp[:, 1:-1, 1:-1] = rows.reshape(b, h, w, c)
    s0, s1, s2, s3 = xp.strides
    view = np.ndarray((b, h // 2, w // 2, 3, 3, c), xp.dtype, xp, 0, (s0, 2 * s1, 2 * s2, s1, s2, s3))
    view.flags.writeable = False
    return view


def fuse(a: Mapping[str, np.ndarray], mm: Engine, bev: np.ndarray, lang: list[LangState],
         speed: np.ndarray, stopped: np.ndarray) -> dict[str, np.ndarray]:
    """The driving network: ``bev`` (B, 7, H, W) uint8, one :class:`LangState` per row,
    ``speed`` m/s and ``stopped`` s (B,) -> ``waypoints`` (B, K, 2) m, ``speed`` (B,) m/s,
    ``stop`` (B,) bool (stop logit > 0) and ``stop_logit`` (B,), all float32 but ``stop``.
    Its three stages, in order: :func:`image` (the BEV alone), :func:`modulated` (with the
    text), :func:`heads` (with the speed and the stop time); :class:`icrsumo.learn.exact.model.
    ExactPolicy` runs them itself to carry stages from one call to the next."""
    return heads(a, mm, modulated(a, mm, image(a, mm, bev).acc, lang), lang, speed, stopped)


@dataclass(frozen=True)
class Background:
    """What an all-zero BEV patch (nothing drawn in its 4x4 pixels) becomes at each stage of
    :func:`image`, float32: the stem's row (C1,), the second convolution's row of a window of
    nine such rows (C2,) and the third convolution's accumulator of nine of those (C3,)."""

    stem: np.ndarray
    c2: np.ndarray
    c3: np.ndarray


def background(a: Mapping[str, np.ndarray], mm: Engine) -> Background:
    """The :class:`Background` rows of a checkpoint (three one-row products)."""
    x1 = requant(mm(np.zeros((1, a["stem.w"].shape[0]), np.float32), "stem"), a["stem.m"], 0,
                 float(a["c2.top"]))
    x2 = requant(mm(np.tile(x1, (1, 9)), "c2"), a["c2.m"], 0, float(a["c3.top"]))
    return Background(x1[0], x2[0], mm(np.tile(x2, (1, 9)), "c3")[0])


@dataclass(frozen=True)
class Image:
    """What :func:`image` computed for a BEV, kept so that the next call can start from it: the
    BEV (B, 7, H, W) uint8, the stem's rows (B, H/4, W/4, C1), the second convolution's
    (B, H/8, W/8, C2) and the third convolution's accumulator before FiLM ``acc``
    (B, H/16, W/16, C3), all float32 integers but the BEV (the array given to :func:`image`,
    which its caller must not change while the Image is kept). Never written to."""

    bev: np.ndarray
    stem: np.ndarray
    c2: np.ndarray
    acc: np.ndarray


def image(a: Mapping[str, np.ndarray], mm: Engine, bev: np.ndarray, bg: Background | None = None,
          before: Image | None = None) -> Image:
    """The part of :func:`fuse` that reads the BEV alone: ``bev`` (B, 7, H, W) uint8 -> its
    :class:`Image` (``acc``: what :func:`modulated` reads).

    Only rows whose inputs are new are multiplied; every row of a product is an exact integer
    whichever rows it is computed with, so the result is the same bits as the dense graph's:

    * most of a BEV is empty (two thirds of its 4x4 patches off the road): a row whose inputs are
      all background (an empty patch; a window of nine background rows, none of them padding) is
      the :class:`Background` row (``bg``, computed here when None);
    * given ``before`` (an earlier call's Image, of a BEV of the same shape), a row whose inputs
      are the same as there (the patch's pixels; the window's nine rows) is its row there: an
      ego standing still sees most of its raster again. The same BEV returns ``before`` itself;
      when more than half of the patches changed (an ego that moves), ``before`` is not used."""
    if bg is None:
        bg = background(a, mm)
    b, _, h, w = bev.shape
    bev = np.ascontiguousarray(bev, dtype=np.uint8)
    empty = ~drawn(bev)
    changed = None
    if before is not None and before.bev.shape == bev.shape:
        changed = drawn(np.bitwise_xor(bev, before.bev))
        n = int(np.count_nonzero(changed))
        if n == 0:
            return before
        if 2 * n > changed.size:
            changed = None
    old = (before.stem, before.c2, before.acc) if changed is not None else (None, None, None)
    x = _rows(a, mm, patch_words(bev), empty, changed, old[0], "stem", bg.stem, packed=True)
    empty, changed = _windows_all(empty), _windows_any(changed)
    x2 = _rows(a, mm, windows3s2(x, b, h // 4, w // 4), empty, changed, old[1], "c2", bg.c2)
    empty, changed = _windows_all(empty), _windows_any(changed)
    acc = _rows(a, mm, windows3s2(x2, b, h // 8, w // 8), empty, changed, old[2], "c3", bg.c3,
                requantise=False)
    return Image(bev, x, x2, acc)


def drawn(bev: np.ndarray) -> np.ndarray:
    """(B, 7, H, W) uint8 -> (B, H/4, W/4) bool: whether any channel has a non-zero pixel in the
    4x4 patch (the channels ORed, then each patch row's four bytes as one uint32)."""
    b, _, h, w = bev.shape
    return np.bitwise_or.reduce(bev, axis=1).view(np.uint32).reshape(b, h // 4, 4, w // 4).any(axis=2)


def _windows(mask: np.ndarray, op: np.ufunc) -> np.ndarray:
    """A layer's row mask (B, h, w) -> ``op`` over each 3x3 stride-2 window of the zero-padded
    mask, (B, h/2, w/2): three rows, then three columns, at a time."""
    b, h, w = mask.shape
    mp = np.zeros((b, h + 2, w + 2), dtype=bool)
    mp[:, 1:-1, 1:-1] = mask
    r = op(op(mp[:, 0:h:2], mp[:, 1:h + 1:2]), mp[:, 2:h + 2:2])
    return op(op(r[:, :, 0:w:2], r[:, :, 1:w + 1:2]), r[:, :, 2:w + 2:2])


def _windows_all(empty: np.ndarray) -> np.ndarray:
    """The next layer's empty rows: windows whose nine rows are all empty (padding is not)."""
    return _windows(empty, np.logical_and)


def _windows_any(changed: np.ndarray | None) -> np.ndarray | None:
    """The next layer's changed rows: windows with any changed row (padding never is)."""
    return None if changed is None else _windows(changed, np.logical_or)


def _rows(a: Mapping[str, np.ndarray], mm: Engine, cols: np.ndarray, empty: np.ndarray,
          changed: np.ndarray | None, before: np.ndarray | None, layer: str, bg_row: np.ndarray,
          requantise: bool = True, packed: bool = False) -> np.ndarray:
    """The output rows (B, h, w, C') of ``layer`` whose inputs are ``cols`` (B, h, w, ...), one
    output row's inputs each (``packed``: :func:`patch_words`' view, whose rows are their bytes):
    an ``empty`` row is ``bg_row``; given ``changed`` and ``before``, a row not changed is
    ``before``'s; the others are multiplied (and requantised for the next layer, or left as the
    raw accumulator)."""
    b, h, w = empty.shape
    todo = ~empty if changed is None else changed & ~empty
    dense = changed is None and bool(todo.all())
    x = cols if dense else cols[todo]              # (B, h, w, ...) or (rows, ...)
    if packed:
        x = _patch_bytes(x)
    acc = mm(x.reshape(-1, math.prod(x.shape[3 if dense else 1:])), layer)
    if requantise:
        nxt = PRODUCTS[PRODUCTS.index(layer) + 1]
        acc = requant(acc, a[f"{layer}.m"], 0, float(a[f"{nxt}.top"]))
    if dense:
        return acc.reshape(b, h, w, -1)
    if changed is None:
        out = np.empty((b, h, w, len(bg_row)), dtype=np.float32)
        out[empty] = bg_row
    else:
        out = before.copy()
        out[empty & changed] = bg_row
    out[todo] = acc
    return out


def modulated(a: Mapping[str, np.ndarray], mm: Engine, acc: np.ndarray,
              lang: list[LangState]) -> np.ndarray:
    """The part of :func:`fuse` that reads the image and the text: :func:`image`'s ``acc``
    (B, h, w, C3), one :class:`LangState` per row -> the fully connected layer's activations
    (B, F) float32 (integers 0..``mlp0.top``)."""
    b, h, w, c3 = acc.shape
    film_m = _rowwise([s.film_m for s in lang])[:, None, :]
    film_b = _rowwise([s.film_b for s in lang])[:, None, :]
    y = np.multiply(acc.reshape(b, h * w, c3), film_m, dtype=np.float32)
    np.add(y, film_b, out=y)
    np.rint(y, out=y)
    np.clip(y, 0, float(a["c4.top"]), out=y)
    x = requant(mm(im2col3s2(y.reshape(b * h * w, c3), b, h, w), "c4"), a["c4.m"], 0, float(a["fc.top"]))
    return requant(mm(x.reshape(b, -1), "fc"), a["fc.m"], 0, float(a["mlp0.top"]))


def _rowwise(rows: list[np.ndarray]) -> np.ndarray:
    """``np.stack(rows)``; one row as a view (a single call's text)."""
    return rows[0][None] if len(rows) == 1 else np.stack(rows)


def heads(a: Mapping[str, np.ndarray], mm: Engine, x: np.ndarray, lang: list[LangState],
          speed: np.ndarray, stopped: np.ndarray) -> dict[str, np.ndarray]:
    """The MLP and the output heads of :func:`fuse`: :func:`modulated`'s ``x`` (B, F), the
    texts' states, ``speed`` m/s and ``stopped`` s (B,) -> :func:`fuse`'s outputs."""
    b = x.shape[0]
    # first MLP layer: image part (a product), language part (per text), speed and stop time
    sp = np.divide(np.asarray(speed, np.float32), np.float32(10.0), dtype=np.float32)
    st = np.divide(np.asarray(stopped, np.float32), np.float32(5.0), dtype=np.float32)
    hid = np.multiply(mm(x, "mlp0"), a["mlp0.k"], dtype=np.float32)
    np.add(hid, _rowwise([s.mlp_l for s in lang]), out=hid)
    np.add(hid, sp[:, None] * a["mlp0.wsp"], out=hid)
    np.add(hid, st[:, None] * a["mlp0.wst"], out=hid)
    x = requant(hid, a["mlp0.m"], 0, float(a["mlp1.top"]))
    x = requant(mm(x, "mlp1"), a["mlp1.m"], 0, float(a["head.top"]))
    acc = mm(x, "head")
    k = a["arc"].shape[0]
    out = np.multiply(acc, a["head.d"], dtype=np.float32)
    wps = out[:, : 2 * k].reshape(b, k, 2).copy()
    np.add(wps[..., 0], a["arc"], out=wps[..., 0])
    speed_out = np.multiply(out[:, 2 * k], np.float32(10.0), dtype=np.float32)
    return {"waypoints": wps, "speed": speed_out, "stop": acc[:, 2 * k + 1] > 0,
            "stop_logit": out[:, 2 * k + 1].copy()}


# ---------------------------------------------------------------------- language (int64)
def _i64(x: np.ndarray) -> np.ndarray:
    return np.asarray(x, dtype=np.int64)


def _dense64(x: np.ndarray, a: Mapping[str, np.ndarray], name: str) -> np.ndarray:
    """``x @ w + b`` of layer ``name`` in int64 (exact in any order)."""
    return _i64(x) @ _i64(a[f"{name}.w"]) + _i64(a[f"{name}.b"])


def _requant64(acc: np.ndarray, m: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """:func:`requant` of int64 accumulations (converted exactly: the exporter bounds them)."""
    return requant(_i64(acc).astype(np.float32), m, lo, hi).astype(np.int64)


def _mlp_lang(a: Mapping[str, np.ndarray], x: np.ndarray) -> np.ndarray:
    """The two-layer language MLP (ReLU between) from int input ``x`` to the language vector."""
    x = _requant64(_dense64(x, a, "lang.l1"), a["lang.l1.m"], 0, float(a["lang.l2.top"]))
    return _requant64(_dense64(x, a, "lang.l2"), a["lang.l2.m"], -LMAX, LMAX)


def _table(t: np.ndarray, pre: np.ndarray) -> np.ndarray:
    """A sigmoid / tanh table (float64, 2*TABLE_HALF+1 entries) at float64 inputs ``pre``."""
    q = np.clip(np.rint(pre * float(TABLE_STEP)), -TABLE_HALF, TABLE_HALF).astype(np.int64)
    return t[q + TABLE_HALF]


def _gru(a: Mapping[str, np.ndarray], d: str, xs: list[np.ndarray]) -> np.ndarray:
    """One GRU direction (``f`` or ``r``) over the int8 embeddings ``xs``: the final hidden
    state in units of 2**-HIDDEN_BITS (int64). Gate pre-activations are exact int64 products
    scaled per channel (float64), sigmoid and tanh come from the checkpoint's tables."""
    one = float(1 << HIDDEN_BITS)
    hq = np.zeros(a[f"gru.{d}.whh"].shape[0], dtype=np.int64)
    sig, tanh = a["gru.sigmoid"], a["gru.tanh"]
    for x in xs:
        gi = (_i64(x) @ _i64(a[f"gru.{d}.wih"])) * a[f"gru.{d}.kih"] + a[f"gru.{d}.bih"]
        gh = (hq @ _i64(a[f"gru.{d}.whh"])) * a[f"gru.{d}.khh"] + a[f"gru.{d}.bhh"]
        n3 = gi.shape[0] // 3
        r = _table(sig, gi[:n3] + gh[:n3])
        z = _table(sig, gi[n3:2 * n3] + gh[n3:2 * n3])
        n = _table(tanh, gi[2 * n3:] + r * gh[2 * n3:])
        h = (1.0 - z) * n + z * (hq / one)
        hq = np.rint(h * one).astype(np.int64)
    return hq


def language(a: Mapping[str, np.ndarray], encoder: str, ids: np.ndarray) -> LangState:
    """The per-text constants of one text's encoder input ``ids`` (token / ngram: (L,) ids,
    0-padded; minilm: the (384,) sentence embedding, float32)."""
    if encoder == "ngram":
        ids = _i64(ids)
        ids = ids[ids > 0]
        total = _i64(a["lang.emb"])[ids].sum(0) if len(ids) else np.zeros(a["lang.emb"].shape[1], np.int64)
        mean = np.divide(np.multiply(total.astype(np.float32), a["lang.emb_m"], dtype=np.float32),
                         np.float32(max(len(ids), 1)), dtype=np.float32)
        lang_q = _mlp_lang(a, np.clip(np.rint(mean), -SMAX, SMAX).astype(np.int64))
    elif encoder == "token":
        ids = _i64(ids)
        n = max(int((ids > 0).sum()), 1)
        emb = _i64(a["lang.emb"])
        xs = [emb[i] for i in ids[:n]]
        hf, hr = _gru(a, "f", xs), _gru(a, "r", xs[::-1])
        hq = np.concatenate([hf, hr]).astype(np.float32)  # both directions, 2**-HIDDEN_BITS units
        lang_q = np.clip(np.rint(np.multiply(hq, a["lang.out_m"], dtype=np.float32)), -LMAX, LMAX
                         ).astype(np.int64)
    elif encoder == "minilm":
        x = np.multiply(np.asarray(ids, np.float32), a["lang.in_m"], dtype=np.float32)
        lang_q = _mlp_lang(a, np.clip(np.rint(x), -SMAX, SMAX).astype(np.int64))
    else:
        raise ValueError(f"no exact language encoder {encoder!r}")
    return constants(a, lang_q)


def constants(a: Mapping[str, np.ndarray], lang_q: np.ndarray) -> LangState:
    """:class:`LangState` of the int8 language vector ``lang_q``: FiLM's gamma and beta and the
    language part of the first MLP layer as exact int64 products, then fixed float64 / float32
    elementwise steps."""
    film = _dense64(lang_q, a, "film").astype(np.float64) * a["film.k"]
    c3 = film.shape[0] // 2
    gamma, beta = film[:c3], film[c3:]
    film_m = ((1.0 + gamma) * a["c3.k"]).astype(np.float32)
    film_b = (beta * a["c3.inv"]).astype(np.float32)
    mlp_l = ((_i64(lang_q) @ _i64(a["mlp0.wl"])).astype(np.float64) * a["mlp0.kl"] + a["mlp0.bias"]
             ).astype(np.float32)
    return LangState(film_m=film_m, film_b=film_b, mlp_l=mlp_l, lang_q=_i64(lang_q))
