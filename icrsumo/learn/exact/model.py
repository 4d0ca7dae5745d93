"""The fast path of an exact checkpoint: :class:`ExactPolicy`, the graph of
:mod:`icrsumo.learn.exact.graph` with float32 matrix products (numpy's BLAS, whatever its kernel,
blocking or thread count: the products are sums of integers below 2**24, exact in any order).
A batch runs as one product per layer; its rows are bitwise those of single calls.

A single call starts from the previous single call: the rows of the image stage
(:func:`icrsumo.learn.exact.graph.image`, three quarters of the products) whose pixels did not
change are that call's (an ego standing still sees most of its raster again), and a BEV byte for
byte the same (a third of the default ICR run's calls) with the same text reuses the modulated
stage too: the same arrays the graph would compute again, so the outputs are the same bits
(``reuse=False`` starts every call afresh, for timing)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .checkpoint import ExactCheckpoint, load
from .graph import PRODUCTS, Image, LangState, background, heads, image, language, modulated

#: distinct texts whose language state is kept (then the cache starts over)
LANG_CACHE = 4096


def limit_blas_threads(threads: int) -> None:
    """Let numpy's BLAS use at most ``threads`` threads in this process (the results are the
    same with any number; one thread per worker keeps parallel episodes from oversubscribing
    the cores, as ONNX Runtime's one-thread sessions did)."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=max(int(threads), 1), user_api="blas")


class FloatEngine:
    """``mm(x, layer)`` = ``x @ W + b`` in float32 (the weights converted once)."""

    def __init__(self, arrays: dict[str, np.ndarray]) -> None:
        self._w = {n: (arrays[f"{n}.w"].astype(np.float32), arrays[f"{n}.b"].astype(np.float32))
                   for n in PRODUCTS}

    def __call__(self, x: np.ndarray, layer: str) -> np.ndarray:
        w, b = self._w[layer]
        out = np.matmul(x.astype(np.float32, copy=False), w)
        out += b
        return out


class ExactPolicy:
    """An exact checkpoint's policy (``path``: its ``.npz`` file, or an :class:`ExactCheckpoint`).
    A call takes ``bev`` (B, 7, H, W) uint8 0/255, instruction ``texts`` (B), ``speed`` (m/s)
    and ``stopped`` (s) (B,) and returns ``waypoints`` (B, K, 2) m, ``speed`` (B,) m/s,
    ``stop`` (B,) bool and ``stop_logit`` (B,). ``engine`` replaces the float32 products (the
    int64 reference: :func:`icrsumo.learn.exact.reference.int64_engine`); ``threads`` limits
    numpy's BLAS threads in the process (:func:`limit_blas_threads`; None leaves them);
    ``reuse``: a single call starts from the previous single call's stages (the module's
    docstring)."""

    def __init__(self, path: Path | str | ExactCheckpoint, engine=None, threads: int | None = 1,
                 reuse: bool = True) -> None:
        if threads:
            limit_blas_threads(threads)
        ck = path if isinstance(path, ExactCheckpoint) else load(path)
        self.checkpoint = ck
        self.cfg, self.meta, self.arrays = ck.config, ck.meta, ck.arrays
        self.mm = engine(self.arrays) if engine is not None else FloatEngine(self.arrays)
        self.text = self.cfg.text_encoder()
        self._lang: dict[str, LangState] = {}
        self.reuse = bool(reuse)
        self._bg = background(self.arrays, self.mm)
        #: the previous single call: its image stage (with its BEV), text and modulated stage
        self._last: tuple[Image, str, np.ndarray] | None = None

    def language(self, texts: list[str]) -> list[LangState]:
        """The :class:`LangState` of each text (computed once per distinct text, alone)."""
        missing = [t for t in dict.fromkeys(texts) if t not in self._lang]
        if missing and len(self._lang) + len(missing) > LANG_CACHE:
            self._lang.clear()
        for text in missing:
            self._lang[text] = language(self.arrays, self.cfg.encoder, self.text.encode(text))
        return [self._lang[t] for t in texts]

    def __call__(self, bev: np.ndarray, texts: list[str], speed: np.ndarray,
                 stopped: np.ndarray) -> dict[str, np.ndarray]:
        bev = np.ascontiguousarray(bev, dtype=np.uint8)
        if bev.ndim != 4 or bev.shape[1] != 7 or bev.shape[2] % 32 or bev.shape[3] % 32:
            raise ValueError(f"bev of shape {bev.shape}: expected (B, 7, H, W), H and W multiples of 32")
        texts = list(texts)
        lang = self.language(texts)
        a, mm, last = self.arrays, self.mm, self._last
        single = self.reuse and len(bev) == 1
        if single:  # kept for the next call: a copy the caller cannot change
            bev = bev.copy()
        before = last[0] if single and last is not None else None
        img = image(a, mm, bev, self._bg, before)
        x = last[2] if before is not None and img is before and texts[0] == last[1] else \
            modulated(a, mm, img.acc, lang)
        if single:
            self._last = (img, texts[0], x)
        return heads(a, mm, x, lang, np.asarray(speed, np.float32).reshape(-1),
                     np.asarray(stopped, np.float32).reshape(-1))
