"""The learned agents' torch models (:mod:`icrsumo.learn.nets`) and the device they run on.

Model (``BevLanguageNet``): a small CNN encodes the BEV raster ``(B, 7, 128, 128)`` (0/1
floats); a language encoder maps the instruction ids ``(B, L)`` to a 128-d vector, which
modulates the CNN's 8x8 feature map (FiLM) and joins the pooled BEV feature, the speed (m/s)
and the stopped time (s) in an MLP. Heads: ``waypoints`` ``(B, K, 2)`` m in the ego frame at
the arc lengths of :data:`icrsumo.learn.labels.ARC_M`, ``speed`` ``(B,)`` target speed m/s,
``stop`` ``(B,)`` logit of "target speed below 0.3 m/s", and ``intent`` ``(B, 6)`` logits of
the instruction's intent (an auxiliary loss that grounds the language vector).

Language encoders: ``token`` (word embeddings + bidirectional GRU, vocabulary of the
training instructions), ``ngram`` (hashed character n-gram embeddings, masked mean, MLP) and
``minilm`` (the frozen pretrained sentence embedding of all-MiniLM-L6-v2, computed outside the
network by :mod:`icrsumo.learn.minilm`, through an MLP).
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from icrsumo.core.errors import InputError, expect
from icrsumo.core.vocab import Intent

from ..config import MINILM_SHAPE, ModelConfig
from ..labels import ARC_M, STOP_BELOW

#: intents of the auxiliary head (the baseline's; others map to follow)
INTENTS = (Intent.FOLLOW, Intent.LEFT, Intent.RIGHT, Intent.STRAIGHT, Intent.LANE_LEFT, Intent.LANE_RIGHT)
_ARC = torch.tensor(ARC_M, dtype=torch.float32)


class _TokenEncoder(nn.Module):
    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.emb = nn.Embedding(len(cfg.vocab), cfg.embed, padding_idx=0)
        self.gru = nn.GRU(cfg.embed, cfg.lang // 2, batch_first=True, bidirectional=True)

    def forward(self, ids: torch.Tensor) -> torch.Tensor:
        lengths = (ids > 0).sum(1).clamp(min=1).cpu()
        packed = nn.utils.rnn.pack_padded_sequence(self.emb(ids), lengths, batch_first=True,
                                                   enforce_sorted=False)
        _, h = self.gru(packed)                     # (2, B, lang/2)
        return torch.cat([h[0], h[1]], dim=1)


class _NgramEncoder(nn.Module):
    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.emb = nn.Embedding(cfg.buckets, cfg.embed, padding_idx=0)
        self.mlp = nn.Sequential(nn.Linear(cfg.embed, cfg.lang), nn.ReLU(), nn.Linear(cfg.lang, cfg.lang))

    def forward(self, ids: torch.Tensor) -> torch.Tensor:
        mask = (ids > 0).unsqueeze(-1).float()
        mean = (self.emb(ids) * mask).sum(1) / mask.sum(1).clamp(min=1.0)
        return self.mlp(mean)


#: a BERT layer's parts here and in Hugging Face's state dicts
BERT_PARTS = {"q": "attention.self.query", "k": "attention.self.key", "v": "attention.self.value",
              "o": "attention.output.dense", "ln1": "attention.output.LayerNorm",
              "ffn_in": "intermediate.dense", "ffn_out": "output.dense", "ln2": "output.LayerNorm"}


class BertLayer(nn.Module):
    """One post-LayerNorm BERT encoder layer (exact GELU), as all-MiniLM-L6-v2 has six:
    ``x`` (B, L, width) and ``bias`` (B, 1, 1, L) additive attention mask (0 for tokens, -1e4 for
    padding) -> (B, L, width). Linear weights are held (in, out) and applied as ``x @ w + b``,
    so that an ONNX export keeps their names (``q_w``, ``q_b``, ... ``ln2_w``, ``ln2_b``)."""

    def __init__(self, width: int = 384, heads: int = 12, ffn: int = 1536, eps: float = 1e-12) -> None:
        super().__init__()
        self.width, self.heads, self.eps = width, heads, eps
        shapes = {"q": (width, width), "k": (width, width), "v": (width, width), "o": (width, width),
                  "ffn_in": (width, ffn), "ffn_out": (ffn, width)}
        for name, (n_in, n_out) in shapes.items():
            setattr(self, f"{name}_w", nn.Parameter(torch.randn(n_in, n_out) * 0.02))
            setattr(self, f"{name}_b", nn.Parameter(torch.zeros(n_out)))
        for name in ("ln1", "ln2"):
            setattr(self, f"{name}_w", nn.Parameter(torch.ones(width)))
            setattr(self, f"{name}_b", nn.Parameter(torch.zeros(width)))

    def _ln(self, x: torch.Tensor, name: str) -> torch.Tensor:
        w, b = getattr(self, f"{name}_w"), getattr(self, f"{name}_b")
        return F.layer_norm(x, (self.width,), w, b, self.eps)

    def _lin(self, x: torch.Tensor, name: str) -> torch.Tensor:
        return x @ getattr(self, f"{name}_w") + getattr(self, f"{name}_b")

    def forward(self, x: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
        d = self.width // self.heads

        def split(t: torch.Tensor) -> torch.Tensor:
            return t.view(t.shape[0], t.shape[1], self.heads, d).transpose(1, 2)

        q, k, v = (split(self._lin(x, n)) for n in ("q", "k", "v"))
        att = torch.softmax(q @ k.transpose(-1, -2) / math.sqrt(d) + bias, dim=-1)
        ctx = (att @ v).transpose(1, 2).reshape(x.shape)
        x = self._ln(x + self._lin(ctx, "o"), "ln1")
        h = F.gelu(self._lin(x, "ffn_in"))
        return self._ln(x + self._lin(h, "ffn_out"), "ln2")


def bert_layer_state(weights: dict[str, np.ndarray], prefix: str) -> dict[str, torch.Tensor]:
    """:class:`BertLayer`'s state dict from a Hugging Face BERT state dict's layer ``prefix``
    (``encoder.layer.5``); linear weights transposed to (in, out)."""
    out = {}
    for name, hf in BERT_PARTS.items():
        w = np.asarray(weights[f"{prefix}.{hf}.weight"], dtype=np.float32)
        out[f"{name}_w"] = torch.from_numpy(np.ascontiguousarray(w if name.startswith("ln") else w.T))
        out[f"{name}_b"] = torch.from_numpy(np.asarray(weights[f"{prefix}.{hf}.bias"], dtype=np.float32))
    return out


def sentence_embedding(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """sentence-transformers' pooling: the mean of token states ``x`` (B, L, D) over ``mask``
    (B, L), L2-normalised -> (B, D)."""
    m = mask[:, :, None].to(x.dtype)
    pooled = (x * m).sum(1) / m.sum(1).clamp(min=1e-9)
    return F.normalize(pooled, p=2.0, dim=1)


class _VectorEncoder(nn.Module):
    """A precomputed sentence embedding ``(B, text_len)`` through a two-layer MLP."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.mlp = nn.Sequential(nn.Linear(cfg.text_len, cfg.lang), nn.ReLU(), nn.Linear(cfg.lang, cfg.lang))

    def forward(self, vec: torch.Tensor) -> torch.Tensor:
        return self.mlp(vec)


class _TunedEncoder(nn.Module):
    """all-MiniLM-L6-v2's last layer, trained, over the frozen token states of its first five
    (``(B, text_len)``: T x 384 values per text, zero rows past its tokens, computed outside
    the network by :mod:`icrsumo.learn.minilm`), pooled as the frozen encoder pools, then the
    MLP of the ``minilm`` encoder. :func:`build_model` starts the layer at the pretrained one."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        width, heads, ffn, eps = MINILM_SHAPE
        self.layer = BertLayer(width, heads, ffn, eps)
        self.mlp = nn.Sequential(nn.Linear(width, cfg.lang), nn.ReLU(), nn.Linear(cfg.lang, cfg.lang))

    def forward(self, states: torch.Tensor) -> torch.Tensor:
        x = states.view(states.shape[0], -1, self.layer.width)
        mask = (x != 0).any(-1)
        bias = (~mask)[:, None, None, :].to(x.dtype) * -1e4
        return self.mlp(sentence_embedding(self.layer(x, bias), mask))


_LANG = {"token": _TokenEncoder, "ngram": _NgramEncoder, "minilm": _VectorEncoder,
         "minilm-tuned": _TunedEncoder}


class BevLanguageNet(nn.Module):
    """BEV CNN + language encoder + FiLM fusion + waypoint / speed / stop / intent heads."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        w = cfg.width
        self.cfg = cfg
        self.lang = _LANG[cfg.encoder](cfg)
        self.stem = nn.Conv2d(7, w, 4, stride=4)                       # 128 -> 32
        self.c2 = nn.Conv2d(w, 2 * w, 3, stride=2, padding=1)          # 32 -> 16
        self.c3 = nn.Conv2d(2 * w, 4 * w, 3, stride=2, padding=1)      # 16 -> 8
        self.film = nn.Linear(cfg.lang, 8 * w)
        self.c4 = nn.Conv2d(4 * w, 4 * w, 3, stride=2, padding=1)      # 8 -> 4
        self.fc = nn.Linear(4 * w * 16, cfg.hidden)
        self.mlp = nn.Sequential(nn.Linear(cfg.hidden + cfg.lang + 2, cfg.hidden), nn.ReLU(),
                                 nn.Linear(cfg.hidden, cfg.hidden), nn.ReLU())
        self.head = nn.Linear(cfg.hidden, 2 * len(ARC_M) + 2)
        self.intent = nn.Linear(cfg.lang, len(INTENTS))

    def forward(self, bev: torch.Tensor, ids: torch.Tensor, speed: torch.Tensor,
                stopped: torch.Tensor) -> dict[str, torch.Tensor]:
        return self.fuse(bev, self.lang(ids), speed, stopped)

    def fuse(self, bev: torch.Tensor, lang: torch.Tensor, speed: torch.Tensor,
             stopped: torch.Tensor, taps: list | None = None) -> dict[str, torch.Tensor]:
        """The forward pass from an already encoded language vector ``lang`` (B, lang);
        ``taps``, when given, receives the seven ReLU activations an exact export calibrates on
        (after the stem, c2, the FiLM, c4, fc and the two MLP layers)."""
        keep = taps.append if taps is not None else (lambda t: None)
        x = F.relu(self.stem(bev))
        keep(x)
        x = F.relu(self.c2(x))
        keep(x)
        x = self.c3(x)
        gamma, beta = self.film(lang).chunk(2, dim=1)
        x = F.relu(x * (1 + gamma[:, :, None, None]) + beta[:, :, None, None])
        keep(x)
        x = F.relu(self.c4(x))
        keep(x)
        x = F.relu(self.fc(x.flatten(1)))
        keep(x)
        h = self.mlp[1](self.mlp[0](torch.cat([x, lang, (speed / 10.0)[:, None], (stopped / 5.0)[:, None]],
                                              dim=1)))
        keep(h)
        h = self.mlp[3](self.mlp[2](h))
        keep(h)
        out = self.head(h)
        k = len(ARC_M)
        wps = out[:, : 2 * k].view(-1, k, 2)
        wps = torch.stack([wps[..., 0] + _ARC.to(wps.device), wps[..., 1]], dim=-1)
        return {"waypoints": wps, "speed": out[:, 2 * k] * 10.0, "stop": out[:, 2 * k + 1],
                "intent": self.intent(lang)}


def unpack_bev(packed: torch.Tensor) -> torch.Tensor:
    """``(B, C, H, W/8)`` uint8 bit-packed rasters -> ``(B, C, H, W)`` float 0/1 (on the same
    device as ``packed``; bit order as ``numpy.packbits``)."""
    shifts = torch.arange(7, -1, -1, device=packed.device, dtype=torch.uint8)
    bits = (packed.unsqueeze(-1) >> shifts) & 1
    return bits.flatten(-2).float()


def build_model(cfg: ModelConfig, seed: int) -> BevLanguageNet:
    """A freshly initialised model; initial weights depend only on ``seed`` (the global torch
    RNG is forked and restored, so the caller's random state is left alone)."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        net = BevLanguageNet(cfg)
    if cfg.encoder == "minilm-tuned":  # the layer to tune starts as the pretrained one
        from ..minilm import encoder

        net.lang.layer.load_state_dict({k: torch.from_numpy(v) for k, v in encoder().last_layer().items()})
    return net


def losses(out: dict[str, torch.Tensor], batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Training losses: L1 on waypoints (m), L1 on target speed (m/s), BCE on stop, CE on
    intent; ``total`` is their weighted sum."""
    wp = (out["waypoints"] - batch["waypoints"]).abs().mean()
    sp = (out["speed"] - batch["target_speed"]).abs().mean()
    stop = F.binary_cross_entropy_with_logits(out["stop"], (batch["target_speed"] < STOP_BELOW).float())
    intent = F.cross_entropy(out["intent"], batch["intent"])
    return {"total": wp + 0.2 * sp + 0.5 * stop + 0.2 * intent, "waypoints": wp, "speed": sp,
            "stop": stop, "intent": intent}


def pick_device(name: str = "auto", file: object = "device", place: str = "") -> torch.device:
    """``auto``: CUDA when available, else CPU; ``cpu``, ``cuda`` or ``cuda:N``. A device that
    is unknown or not on this machine (:func:`icrsumo.core.devices.check_device`) is an InputError
    naming ``file`` and ``place`` (the config key or the command-line option it came from)."""
    from icrsumo.core.devices import check_device

    expect(name, str, file, place, "the device", "use cpu, cuda, cuda:N or auto")
    try:
        check_device(name, str(file))
    except InputError as err:
        raise InputError(file, place, f"device {name!r}: {err.problem}", err.fix) from None
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def parameter_count(model: nn.Module) -> int:
    """How many numbers ``model``'s parameters hold."""
    return sum(p.numel() for p in model.parameters())
