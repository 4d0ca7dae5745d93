"""The int64 reference of the exact graph: every matrix product as int64 arithmetic, which has
no rounding, so its result does not depend on the order of the sums. Used with
:class:`icrsumo.learn.exact.model.ExactPolicy` (``engine=int64_engine``) it computes what the
float32 fast path must equal bit for bit; it also checks each product's result against the
2**24 limit the exporter proved for it."""

from __future__ import annotations

import numpy as np

from .graph import EXACT_LIMIT, PRODUCTS


def int64_engine(arrays: dict[str, np.ndarray]):
    """``mm(x, layer)`` = ``x @ W + b`` in int64, returned as float32 (exact below 2**24)."""
    w = {n: (arrays[f"{n}.w"].astype(np.int64), arrays[f"{n}.b"].astype(np.int64)) for n in PRODUCTS}

    def mm(x: np.ndarray, layer: str) -> np.ndarray:
        xi = np.asarray(x)
        if xi.dtype.kind == "f":
            if not np.array_equal(xi, np.rint(xi)):
                raise ArithmeticError(f"{layer}: input holds a non-integer")
            xi = xi.astype(np.int64)
        wl, bl = w[layer]
        acc = xi.astype(np.int64) @ wl + bl
        if acc.size and int(np.abs(acc).max()) >= EXACT_LIMIT:
            raise ArithmeticError(f"{layer}: a sum reached 2**24")
        return acc.astype(np.float32)

    return mm
