"""Inference of a float checkpoint (:mod:`icrsumo.learn.nets`): :class:`Policy` on the CPU (ONNX
Runtime or torch) or a GPU, and the in-memory ONNX export of the model's fusion pass."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from icrsumo.core.errors import InputError

from ..config import short_repr as _short
from .checkpoint import read_checkpoint
from .models import BevLanguageNet, pick_device

#: rows of every forward pass on a GPU: batches are padded (or split) to it
GPU_BATCH = 32


#: inference runtimes of :class:`Policy` on the CPU
RUNTIMES = ("onnx", "torch")


class _FuseGraph(nn.Module):
    """:meth:`BevLanguageNet.fuse` as the exported graph: uint8 BEV in, stop probability out."""

    def __init__(self, net: BevLanguageNet) -> None:
        super().__init__()
        self.net = net

    def forward(self, bev: torch.Tensor, lang: torch.Tensor, speed: torch.Tensor,
                stopped: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        out = self.net.fuse(bev.float() * (1.0 / 255.0), lang, speed, stopped)
        return out["waypoints"], out["speed"], torch.sigmoid(out["stop"])


def onnx_bytes(model: BevLanguageNet) -> bytes:
    """The ONNX graph (opset 17, batch dimension free) of ``model``'s fusion pass
    (:class:`_FuseGraph`), exported in memory by torch's TorchScript-based exporter: inputs
    ``bev`` (B, 7, H, W) uint8, ``lang`` (B, lang), ``speed`` and ``stopped`` (B,); outputs
    ``waypoints`` (B, K, 2) m, ``speed_out`` (B,) m/s, ``stop_prob`` (B,)."""
    import io
    import warnings

    from ..runtime import INPUTS, OUTPUTS

    h = w = 128
    args = (torch.zeros(1, 7, h, w, dtype=torch.uint8), torch.zeros(1, model.cfg.lang),
            torch.zeros(1), torch.zeros(1))
    buf = io.BytesIO()
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")  # the exporter's deprecation notice
        torch.onnx.export(_FuseGraph(model).eval(), args, buf, dynamo=False, opset_version=17,
                          input_names=list(INPUTS), output_names=list(OUTPUTS),
                          dynamic_axes={n: {0: "batch"} for n in (*INPUTS, *OUTPUTS)})
    return buf.getvalue()


class Policy:
    """Inference wrapper of an exported checkpoint on ``device`` (``cpu``, ``cuda`` or
    ``auto``). The language vector of each distinct instruction text is computed by torch once,
    alone, and cached. On the CPU the rest of the network runs in ``runtime`` ``onnx`` (ONNX
    Runtime, one thread: :mod:`icrsumo.learn.runtime`; the default, about 3x faster per call at
    batch size 1) or ``torch`` (``torch.inference_mode``); the two agree within float rounding,
    not bitwise. On the CPU a batch runs sample by sample, so that results are bitwise those of
    single calls. On a GPU (torch) a batch runs in forward passes of exactly
    :data:`GPU_BATCH` rows (zero-padded), with cuDNN's deterministic algorithms and no TF32, so
    that a sample's output does not depend on how many or which other samples share its batch;
    GPU and CPU results differ by float rounding."""

    def __init__(self, path: Path, threads: int | None = 1, device: str = "cpu",
                 runtime: str = "onnx") -> None:
        if runtime not in RUNTIMES:
            raise InputError("runtime", "", f"unknown inference runtime {_short(runtime)}",
                             f"use one of {', '.join(RUNTIMES)}")
        self.device = pick_device(device)
        ck, self.cfg = read_checkpoint(path)
        if threads:
            torch.set_num_threads(threads)
        self.meta = ck.get("meta", {})
        self.model = BevLanguageNet(self.cfg)
        self.model.load_state_dict(ck["model"])
        self.model.eval()
        if self.device.type == "cuda":
            torch.backends.cudnn.deterministic = True
            torch.backends.cudnn.benchmark = False
            torch.backends.cudnn.allow_tf32 = False
            torch.backends.cuda.matmul.allow_tf32 = False
        self.model.to(self.device)
        self.runtime = runtime if self.device.type == "cpu" else "torch"
        self._ort = None
        if self.runtime == "onnx":
            from ..runtime import OrtFuse

            self._ort = OrtFuse(onnx_bytes(self.model), threads or 1)
        self.text = self.cfg.text_encoder()
        self._lang: dict[str, torch.Tensor] = {}
        self._lang_np: dict[str, np.ndarray] = {}

    def language(self, texts: list[str]) -> torch.Tensor:
        """``(B, lang)`` language vectors of ``texts`` (cached per text)."""
        missing = [t for t in dict.fromkeys(texts) if t not in self._lang]
        if missing and len(self._lang) > 4096:
            self._lang.clear()
            self._lang_np.clear()
        for text in missing:  # one at a time: a text's vector never depends on the others
            with torch.inference_mode():
                ids = torch.from_numpy(self.text.encode_many([text])).to(self.device)
                self._lang[text] = vec = self.model.lang(ids)[0]
                if self._ort is not None:  # ONNX Runtime's (1, lang) input, made once per text
                    self._lang_np[text] = vec[None].numpy()
        return torch.stack([self._lang[t] for t in texts])

    def __call__(self, bev: np.ndarray, texts: list[str], speed: np.ndarray,
                 stopped: np.ndarray) -> dict[str, np.ndarray]:
        """Batched forward: ``bev`` (B, 7, H, W) uint8 0/255, instruction ``texts`` (B),
        ``speed`` (m/s) and ``stopped`` (s) (B,) -> numpy ``waypoints`` (B, K, 2) m,
        ``speed`` (B,) m/s, ``stop_prob`` (B,)."""
        if self._ort is not None:
            return self._onnx(bev, texts, speed, stopped)
        lang = self.language(texts)
        dev = self.device
        speed = torch.from_numpy(np.asarray(speed, dtype=np.float32)).to(dev)
        stopped = torch.from_numpy(np.asarray(stopped, dtype=np.float32)).to(dev)
        with torch.inference_mode():
            b = torch.from_numpy(np.ascontiguousarray(bev)).to(dev).float().mul_(1.0 / 255.0)
            if dev.type == "cpu":
                # one sample at a time: bitwise the same as acting alone (CPU kernels may round
                # differently for other batch sizes); batching pays off on a GPU only
                outs = [self.model.fuse(b[i:i + 1], lang[i:i + 1], speed[i:i + 1], stopped[i:i + 1])
                        for i in range(len(b))]
            else:
                outs = [self._padded(b[i:i + GPU_BATCH], lang[i:i + GPU_BATCH], speed[i:i + GPU_BATCH],
                                     stopped[i:i + GPU_BATCH]) for i in range(0, len(b), GPU_BATCH)]
            out = {k: torch.cat([o[k] for o in outs]) for k in outs[0]}
            return {"waypoints": out["waypoints"].cpu().numpy(), "speed": out["speed"].cpu().numpy(),
                    "stop_prob": torch.sigmoid(out["stop"]).cpu().numpy()}

    def _onnx(self, bev: np.ndarray, texts: list[str], speed: np.ndarray,
              stopped: np.ndarray) -> dict[str, np.ndarray]:
        """:meth:`__call__` in ONNX Runtime, one sample at a time (as torch on the CPU)."""
        if any(t not in self._lang_np for t in texts):
            self.language(texts)
        bev = np.ascontiguousarray(bev, dtype=np.uint8)
        speed = np.asarray(speed, dtype=np.float32).reshape(-1)
        stopped = np.asarray(stopped, dtype=np.float32).reshape(-1)
        outs = [self._ort(bev[i:i + 1], self._lang_np[t], speed[i:i + 1], stopped[i:i + 1])
                for i, t in enumerate(texts)]
        if len(outs) == 1:
            return outs[0]
        return {k: np.concatenate([o[k] for o in outs]) for k in outs[0]}

    def _padded(self, bev: torch.Tensor, lang: torch.Tensor, speed: torch.Tensor,
                stopped: torch.Tensor) -> dict[str, torch.Tensor]:
        """One forward pass of exactly GPU_BATCH rows (zero rows appended); the first
        ``len(bev)`` rows of each output."""
        n, pad = len(bev), GPU_BATCH - len(bev)
        if pad:
            bev, lang, speed, stopped = (torch.cat([x, x.new_zeros((pad, *x.shape[1:]))])
                                         for x in (bev, lang, speed, stopped))
        return {k: v[:n] for k, v in self.model.fuse(bev, lang, speed, stopped).items()}
