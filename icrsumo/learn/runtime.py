"""ONNX Runtime inference of a learned agent's network (and of the pretrained sentence
encoder) on the CPU; the only module of the package that imports onnxruntime.

At batch size 1 a small network's cost in torch is mostly framework overhead per operator.
:class:`OrtFuse` runs the same graph (the BEV encoder, the FiLM fusion and the heads: every
part of :meth:`icrsumo.learn.nets.models.BevLanguageNet.fuse`, exported from the torch model in
memory by :func:`icrsumo.learn.nets.policy.onnx_bytes`) in one ONNX Runtime session with one thread
and sequential execution, so that a call is deterministic and its result depends only on its
inputs. Its outputs equal torch's within float rounding (tested: waypoints within 1e-4 m);
the language vector is still computed by torch, once per distinct text.
"""

from __future__ import annotations

import numpy as np
import onnxruntime as ort

#: names of the graph's inputs and outputs (fixed by :func:`icrsumo.learn.nets.policy.onnx_bytes`)
INPUTS = ("bev", "lang", "speed", "stopped")
OUTPUTS = ("waypoints", "speed_out", "stop_prob")


def cpu_session(model: bytes | str, threads: int = 1) -> ort.InferenceSession:
    """An ONNX Runtime CPU session of ``model`` (graph bytes or a file path) with ``threads``
    intra-op threads, sequential execution and every graph optimisation (the sentence encoder of
    :mod:`icrsumo.learn.minilm` uses it too)."""
    so = ort.SessionOptions()
    so.intra_op_num_threads = max(int(threads), 1)
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.log_severity_level = 3
    so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(model, so, providers=["CPUExecutionProvider"])


class OrtFuse:
    """One ONNX Runtime CPU session of an exported fusion graph (``model``: the ONNX bytes).

    A call takes ``bev`` (B, 7, H, W) uint8 0/255, ``lang`` (B, lang) float32, ``speed`` m/s
    and ``stopped`` s (B,) float32 and returns ``waypoints`` (B, K, 2) m, target ``speed``
    (B,) m/s and ``stop_prob`` (B,)."""

    def __init__(self, model: bytes, threads: int = 1) -> None:
        self.session = cpu_session(model, threads)
        names = tuple(i.name for i in self.session.get_inputs())
        if names != INPUTS:
            raise ValueError(f"ONNX graph inputs {names}, expected {INPUTS}")
        self._run = self.session.run

    def __call__(self, bev: np.ndarray, lang: np.ndarray, speed: np.ndarray,
                 stopped: np.ndarray) -> dict[str, np.ndarray]:
        wps, v, p = self._run(OUTPUTS, {"bev": bev, "lang": lang, "speed": speed, "stopped": stopped})
        return {"waypoints": wps, "speed": v, "stop_prob": p}
