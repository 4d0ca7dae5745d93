"""The learned agents' model configuration (:class:`ModelConfig`), checked when a checkpoint
is read; no torch, so that exact checkpoints (:mod:`icrsumo.learn.exact`) load without it."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

from icrsumo.core.errors import InputError, expect

from .text import ENCODERS, TextEncoder

#: all-MiniLM-L6-v2's layer shape: width, attention heads, feed-forward width, LayerNorm epsilon
MINILM_SHAPE = (384, 12, 1536, 1e-12)

_CHECKPOINT_FIX = "use a model.pt written by icrsumo train, or a shipped agent (bev-token, bev-ngram, ...)"


@dataclass(frozen=True)
class ModelConfig:
    """Architecture: language ``encoder`` (token / ngram), ids per text ``text_len``, hash
    ``buckets`` (ngram), ``vocab`` (token), embedding size ``embed``, language vector ``lang``,
    CNN base width ``width``, MLP width ``hidden``."""

    encoder: str = "ngram"
    text_len: int = 160
    buckets: int = 8192
    vocab: tuple[str, ...] = field(default=())
    embed: int = 64
    lang: int = 128
    width: int = 32
    hidden: int = 256

    def text_encoder(self) -> TextEncoder:
        return TextEncoder(self.encoder, self.text_len, self.vocab, self.buckets)


def config_dict(cfg: ModelConfig) -> dict:
    """``cfg`` as a JSON-ready dict (the vocabulary as a list)."""
    d = asdict(cfg)
    d["vocab"] = list(cfg.vocab)
    return d


def short_repr(value: object) -> str:
    """``repr(value)``, cut to 60 characters."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def config_from_dict(d: object, path: Path | str = "checkpoint", place: str = "config",
                     fix: str = _CHECKPOINT_FIX) -> ModelConfig:
    """The :class:`ModelConfig` of a checkpoint's ``config`` dict; unknown keys, values of the
    wrong type and out-of-range sizes are InputErrors naming ``path`` and the key."""
    d = dict(expect(d, dict, path, place, "the model config", fix))
    known = {f.name: f for f in fields(ModelConfig)}
    for key in d:
        if key not in known:
            raise InputError(path, f"{place}.{key}", "unknown model option", fix)
    vocab = expect(d.get("vocab", []), (list, tuple), path, f"{place}.vocab", "the vocabulary", fix)
    d["vocab"] = tuple(vocab)
    for i, w in enumerate(d["vocab"]):
        expect(w, str, path, f"{place}.vocab[{i}]", "a word", fix)
    for key, f in known.items():
        if key != "vocab" and key in d:
            expect(d[key], {"str": str, "int": int}[f.type], path, f"{place}.{key}", "the value", fix)
    cfg = ModelConfig(**d)
    if cfg.encoder not in ENCODERS:
        raise InputError(path, f"{place}.encoder", f"unknown encoder {short_repr(cfg.encoder)}", fix)
    for key in ("text_len", "embed", "width", "hidden"):
        if getattr(cfg, key) < 1:
            raise InputError(path, f"{place}.{key}", f"{getattr(cfg, key)} is not a positive size", fix)
    if cfg.lang < 2 or cfg.lang % 2:
        raise InputError(path, f"{place}.lang", f"{cfg.lang} is not a positive even size", fix)
    if cfg.encoder == "minilm-tuned" and cfg.text_len % MINILM_SHAPE[0]:
        raise InputError(path, f"{place}.text_len", f"{cfg.text_len} is not a whole number of "
                         f"{MINILM_SHAPE[0]}-value token states", fix)
    if cfg.encoder == "ngram" and cfg.buckets < 2:
        raise InputError(path, f"{place}.buckets", f"{cfg.buckets} hash buckets (at least 2)", fix)
    if cfg.encoder == "token" and len(cfg.vocab) < 2:
        raise InputError(path, f"{place}.vocab", f"{len(cfg.vocab)} words (at least <pad> and <unk>)", fix)
    return cfg
