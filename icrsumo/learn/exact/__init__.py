"""Exact (CPU-independent) inference of the learned agents, without torch.

An exact checkpoint (``NAME.npz``, :mod:`.checkpoint`) holds a learned agent's network with
integer weights and activations: every sum the network computes is a sum of integers whose
partial sums stay below 2**24, so float32 arithmetic carries it exactly, and any summation
order, SIMD width, FMA, kernel blocking, thread count or batch size gives the same bits.
Everything else is elementwise IEEE-754 arithmetic in a fixed order (multiply, add, divide,
round half to even, clip), which every conforming CPU computes identically; no transcendental
function is evaluated at run time (the GRU's sigmoid and tanh are tables made by the exporter).

* :mod:`.graph`: the network as integer graph, written once over a pluggable matrix product;
* :mod:`.model`: :class:`ExactPolicy`, the fast path (float32 BLAS, batched);
* :mod:`.reference`: the int64 matrix product (order-free) that proves the fast path;
* :mod:`.checkpoint`: the file format (npz + JSON, loaded with ``allow_pickle=False``);
* :mod:`.quantize`: ``icrsumo export-exact``, a float checkpoint made exact (needs torch);
* :mod:`.proof`: the fast path against the reference on recorded observations.

The sentence encoder of the MiniLM agents is exact too (:mod:`icrsumo.learn.minilm`).
"""
