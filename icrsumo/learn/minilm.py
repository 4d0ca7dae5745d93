"""The pretrained sentence encoder of ``bev-minilm``: all-MiniLM-L6-v2 (Apache-2.0; credit and
licence in ``encoders/NOTICE``), tokenized by the ``tokenizers`` library (the ``icrsumo[minilm]``
extra) and computed exactly in numpy: the same bits on every CPU, no ONNX Runtime, no torch.

``SentenceEncoder.embed(text)`` is the (384,) float32 L2-normalised mean of the last hidden
states, as sentence-transformers computes it; ``states(text)`` the (tokens, 384) token states
that enter the last layer (the ``minilm-tuned`` encoder runs its own fine-tuned copy of that
layer on them). One text at a time, so a text's arrays never depend on the others.

The weights (``encoders/all-minilm-l6-v2.exact.npz``, made by ``tools/export_minilm.py``) are
8-bit per output channel with zero points, embeddings 8-bit per tensor. Per text:

* every matrix product multiplies integers: activations quantised per tensor to int16
  (``scale = max|x| / 32767``), weights ``q - zero_point``; the sums stay below 2**53, so float64
  BLAS is exact in any order (the int64 product :func:`int64_mm` proves it in the tests);
* LayerNorm sums fixed-point integers (``rint(x * 2**12)``) exactly, then divides and takes one
  IEEE square root; the attention's softmax takes ``exp`` from a table (step 1/64 over
  [-16, 0], linear interpolation), sums 20-bit fixed-point weights exactly and applies them to
  int16 values; GELU is a table too (step 1/64 over [-8, 8], linear interpolation; ``x`` above,
  0 below); mean pooling sums fixed-point states exactly and L2-normalises with one square root.

Everything else is elementwise IEEE-754 arithmetic in a fixed order, which every conforming CPU
computes identically (no transcendental function is evaluated at run time).
"""

from __future__ import annotations

import importlib.util
import math
from functools import cache
from pathlib import Path

import numpy as np

from icrsumo.core.errors import InputError

ENCODERS_DIR = Path(__file__).resolve().parent / "encoders"
MODEL = ENCODERS_DIR / "all-minilm-l6-v2.exact.npz"
TOKENIZER = ENCODERS_DIR / "tokenizer.json"
FORMAT = "icrsumo-exact-minilm/1"
#: embedding size
DIM = 384
#: tokens a text is cut to (the model's training length)
MAX_TOKENS = 128
EXTRA = "pip install 'icrsumo[minilm]'"
LAYERS, WIDTH, HEADS = 6, 384, 12
#: activations are quantised to -Q16..Q16 per tensor before a product
Q16 = 32767
#: LayerNorm and pooling work on x * 2**FIXED rounded to integers
FIXED = 12
#: softmax weights are carried as integers of 2**SOFT_BITS units
SOFT_BITS = 20
#: tables: (lo, hi, steps per unit)
EXP_TABLE, GELU_TABLE = (-16.0, 0.0, 64), (-8.0, 8.0, 64)
#: the weight matrices of one encoder layer, in the order the checkpoint stores them
LAYER_PARTS = ("q", "k", "v", "o", "ffn_in", "ffn_out")
_FIX = "reinstall icrsumo (the file ships with it), or rebuild it with python tools/export_minilm.py"


def tokenizers_missing() -> bool:
    """Whether the ``tokenizers`` library (the ``icrsumo[minilm]`` extra) is not installed."""
    return importlib.util.find_spec("tokenizers") is None


def table(fn, spec: tuple[float, float, int]) -> np.ndarray:
    """``fn`` at ``lo, lo + 1/steps, ..., hi`` (float64; computed once, when the file is built)."""
    lo, hi, steps = spec
    n = int(round((hi - lo) * steps))
    return np.array([fn(lo + i / steps) for i in range(n + 1)], dtype=np.float64)


def interp(t: np.ndarray, spec: tuple[float, float, int], x: np.ndarray) -> np.ndarray:
    """Table ``t`` at float64 ``x`` (clipped to the table's range), linearly interpolated: a
    fixed sequence of IEEE operations, the same bits on every CPU."""
    lo, hi, steps = spec
    u = (np.clip(x, lo, hi) - lo) * float(steps)
    i = np.minimum(np.floor(u), len(t) - 2)
    f = u - i
    i = i.astype(np.int64)
    a = t[i]
    return a + f * (t[i + 1] - a)


def float_mm(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The fast product: float64 BLAS on integer-valued arrays (exact below 2**53)."""
    return np.matmul(a, b)


def int64_mm(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The reference product: int64 (no rounding, any order), checked below 2**53."""
    ai, bi = np.asarray(a), np.asarray(b)
    for x in (ai, bi):
        if x.dtype.kind == "f" and not np.array_equal(x, np.rint(x)):
            raise ArithmeticError("a product's input holds a non-integer")
    out = np.matmul(ai.astype(np.int64), bi.astype(np.int64))
    if out.size and int(np.abs(out).max()) >= 1 << 53:
        raise ArithmeticError("a sum reached 2**53")
    return out.astype(np.float64)


def _q16(x: np.ndarray) -> tuple[np.ndarray, float]:
    """``x`` quantised per tensor to integers in -Q16..Q16 (float64) and its scale."""
    top = float(np.abs(x).max())
    scale = top / Q16 if top > 0 else 1.0
    return np.rint(x / scale), scale


def _fixed(x: np.ndarray) -> np.ndarray:
    """``rint(x * 2**FIXED)`` as int64 (checked: |x| < 2**10, so LayerNorm's sums fit int64)."""
    if x.size and float(np.abs(x).max()) >= 1024.0:
        raise ArithmeticError("a hidden state of 1024 or more")
    return np.rint(x * float(1 << FIXED)).astype(np.int64)


def layer_norm(x: np.ndarray, w: np.ndarray, b: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    """LayerNorm over the last axis: integer sums of the fixed-point ``x``, then IEEE steps."""
    xq = _fixed(x)
    n = x.shape[-1]
    s1 = xq.sum(-1, keepdims=True)
    num = n * (xq * xq).sum(-1, keepdims=True) - s1 * s1            # n^2 var * 2^(2 FIXED), exact
    var = num.astype(np.float64) / float(n * n) / float(1 << (2 * FIXED))
    centred = (n * xq - s1).astype(np.float64) / float(n) / float(1 << FIXED)
    return centred / np.sqrt(var + eps) * w.astype(np.float64) + b.astype(np.float64)


class SentenceEncoder:
    """all-MiniLM-L6-v2 over the arrays of ``model`` and the tokenizer ``tokenizer``; ``mm``
    replaces the float64 products (:func:`int64_mm`, the reference). InputErrors name the
    missing or damaged file, or the missing ``tokenizers`` library, and the fix."""

    def __init__(self, model: Path = MODEL, tokenizer: Path = TOKENIZER, mm=float_mm) -> None:
        if tokenizers_missing():
            raise InputError("tokenizers", "", "the bev-minilm agent's tokenizer library is not installed",
                             EXTRA)
        from tokenizers import Tokenizer

        for f in (model, tokenizer):
            if not Path(f).is_file():
                raise InputError(f, "", "the sentence encoder's file is missing", _FIX)
        try:
            self.tokenizer = Tokenizer.from_file(str(tokenizer))
        except Exception as err:  # noqa: BLE001 - the library's own errors, in one line
            raise InputError(tokenizer, "", f"not a readable tokenizer ({' '.join(str(err).split())[:100]})",
                             _FIX) from None
        self.tokenizer.no_padding()
        self.tokenizer.enable_truncation(MAX_TOKENS)
        self.model, self.a, self.mm = Path(model), _read(Path(model)), mm
        # each product's weights as float64 integers (q - zero point), scales and bias, converted once
        self.w, self.scale, self.bias = {}, {}, {}
        for i in range(LAYERS):
            for part in LAYER_PARTS:
                p = f"layers.{i}.{part}"
                w = self.a[f"{p}.q"].astype(np.int16) - self.a[f"{p}.zero"]
                self.w[p] = w.astype(np.float64)
                self.scale[p] = self.a[f"{p}.scale"].astype(np.float64)
                self.bias[p] = self.a[f"{p}.b"].astype(np.float64)

    def _linear(self, x: np.ndarray, name: str) -> np.ndarray:
        xq, s = _q16(x)
        acc = self.mm(xq, self.w[name])
        return acc * (s * self.scale[name]) + self.bias[name]

    def _layer(self, x: np.ndarray, i: int) -> np.ndarray:
        p, a = f"layers.{i}.", self.a
        n, d = x.shape[0], WIDTH // HEADS
        q, k, v = (self._linear(x, p + part) for part in ("q", "k", "v"))
        (qq, sq), (kq, sk), (vq, sv) = _q16(q), _q16(k), _q16(v)
        heads = lambda t: t.reshape(n, HEADS, d).transpose(1, 0, 2)  # noqa: E731 - (H, n, d)
        scores = self.mm(heads(qq), heads(kq).transpose(0, 2, 1)) * (sq * sk / math.sqrt(d))
        e = interp(a["exp_table"], EXP_TABLE, scores - scores.max(-1, keepdims=True))
        eq = np.rint(e * float(1 << SOFT_BITS))
        ctx = self.mm(eq, heads(vq)) * sv / eq.sum(-1, keepdims=True)          # (H, n, d)
        ctx = ctx.transpose(1, 0, 2).reshape(n, WIDTH)
        x = layer_norm(x + self._linear(ctx, p + "o"), a[p + "ln1.w"], a[p + "ln1.b"])
        h = self._linear(x, p + "ffn_in")
        gelu = interp(a["gelu_table"], GELU_TABLE, h)
        h = np.where(h > GELU_TABLE[1], h, np.where(h < GELU_TABLE[0], 0.0, gelu))
        return layer_norm(x + self._linear(h, p + "ffn_out"), a[p + "ln2.w"], a[p + "ln2.b"])

    def _embeddings(self, ids: np.ndarray) -> np.ndarray:
        a = self.a
        word = (a["word.q"][ids].astype(np.int16) - a["word.zero"]).astype(np.float32) * a["word.scale"]
        pos = (a["position.q"][: len(ids)].astype(np.int16) - a["position.zero"]).astype(np.float32) * \
            a["position.scale"]
        x = (word + pos + a["token_type"]).astype(np.float64)
        return layer_norm(x, a["emb_ln.w"], a["emb_ln.b"])

    def _ids(self, text: str) -> np.ndarray:
        return np.asarray(self.tokenizer.encode(text).ids, dtype=np.int64)

    def states(self, text: str) -> np.ndarray:
        """(tokens, 384) float32 token states entering the last layer."""
        x = self._embeddings(self._ids(text))
        for i in range(LAYERS - 1):
            x = self._layer(x, i)
        return x.astype(np.float32)

    def last_layer(self) -> dict[str, np.ndarray]:
        """The encoder's last layer as :class:`icrsumo.learn.nets.models.BertLayer`'s float32 state
        dict, its 8-bit weights dequantised per output channel: where fine-tuning starts."""
        p, out = f"layers.{LAYERS - 1}.", {}
        for part in LAYER_PARTS:
            out[f"{part}_w"] = (self.w[p + part] * self.a[f"{p}{part}.scale"]).astype(np.float32)
            out[f"{part}_b"] = self.a[f"{p}{part}.b"].astype(np.float32)
        for ln in ("ln1", "ln2"):
            out[f"{ln}_w"] = self.a[f"{p}{ln}.w"].astype(np.float32)
            out[f"{ln}_b"] = self.a[f"{p}{ln}.b"].astype(np.float32)
        return out

    def embed_many(self, texts: list[str]) -> np.ndarray:
        """(N, DIM) float32 embeddings, one text at a time."""
        return np.stack([self.embed(t) for t in texts]) if texts else np.zeros((0, DIM), np.float32)

    def embed(self, text: str) -> np.ndarray:
        """(384,) float32 L2-normalised mean of the last layer's token states."""
        x = self._embeddings(self._ids(text))
        for i in range(LAYERS):
            x = self._layer(x, i)
        pooled = _fixed(x).sum(0)                                  # exact: n * mean * 2**FIXED
        norm2 = sum(int(v) * int(v) for v in pooled)               # Python ints: no overflow
        return (pooled.astype(np.float64) / math.sqrt(float(norm2) or 1.0)).astype(np.float32)


def _read(path: Path) -> dict[str, np.ndarray]:
    """The encoder file's arrays (``allow_pickle=False``), its format and array names checked."""
    try:
        with np.load(path, allow_pickle=False) as z:
            a = {k: z[k] for k in z.files}
    except Exception as err:  # noqa: BLE001 - numpy's and zipfile's errors, in one line
        raise InputError(path, "", f"not a readable encoder file ({type(err).__name__}: "
                         f"{' '.join(str(err).split())[:100]})", _FIX) from None
    fmt = a.pop("__format__", np.zeros(0, np.uint8))
    if fmt.dtype != np.uint8 or fmt.tobytes() != FORMAT.encode():
        raise InputError(path, "__format__", "not an icrsumo sentence encoder file", _FIX)
    want = {"word.q", "word.zero", "word.scale", "position.q", "position.zero", "position.scale",
            "token_type", "emb_ln.w", "emb_ln.b", "exp_table", "gelu_table",
            *(f"layers.{i}.{part}.{k}" for i in range(LAYERS) for part in LAYER_PARTS
              for k in ("q", "zero", "scale", "b")),
            *(f"layers.{i}.{ln}.{k}" for i in range(LAYERS) for ln in ("ln1", "ln2") for k in ("w", "b"))}
    missing = sorted(want - set(a))
    if missing:
        raise InputError(path, missing[0], f"missing ({len(missing)} arrays in all)", _FIX)
    return a


def write(arrays: dict[str, np.ndarray], path: Path = MODEL) -> None:
    """Write the encoder file (``__format__`` first)."""
    import io

    from icrsumo.core.fsio import write_atomic

    buf = io.BytesIO()
    np.savez(buf, __format__=np.frombuffer(FORMAT.encode(), np.uint8), **arrays)
    write_atomic(Path(path), buf.getvalue())


@cache
def encoder() -> SentenceEncoder:
    """The process's shared encoder (loaded on first use)."""
    return SentenceEncoder()
