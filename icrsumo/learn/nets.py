"""Torch models of the learned agents, their checkpoints and one training step; the only
module of the package that imports torch.

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

Checkpoints are plain dicts of tensors, strings and numbers, read with
``torch.load(..., weights_only=True)``; a file that is missing, empty, truncated, not a torch
file, refused by that safe loader, or whose weights do not fit its model config is an
:class:`icrsumo.errors.InputError` naming the file (:func:`load`, :func:`read_checkpoint`).
"""

from __future__ import annotations

import math
import pickle
import re
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from ..errors import Field, InputError, expect
from ..fsio import unreadable
from ..vocab import Intent
from .config import _CHECKPOINT_FIX, MINILM_SHAPE, ModelConfig, config_from_dict
from .config import config_dict as _cfg_dict
from .config import short_repr as _short
from .labels import ARC_M, STOP_BELOW

CHECKPOINT_FORMAT = "icrsumo-agent/1"
#: format of the training state OUT/last.pt
STATE_FORMAT = CHECKPOINT_FORMAT + "+train"
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
        from .minilm import encoder

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
    is unknown or not on this machine (:func:`icrsumo.devices.check_device`) is an InputError
    naming ``file`` and ``place`` (the config key or the command-line option it came from)."""
    from ..devices import check_device

    expect(name, str, file, place, "the device", "use cpu, cuda, cuda:N or auto")
    try:
        check_device(name, str(file))
    except InputError as err:
        raise InputError(file, place, f"device {name!r}: {err.problem}", err.fix) from None
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


class Trainer:
    """Model + AdamW + step counter on ``device``; saves and resumes its whole state."""

    def __init__(self, cfg: ModelConfig, seed: int, lr: float, weight_decay: float, steps: int,
                 device: torch.device, lr_tuned: float = 1e-4) -> None:
        self.cfg, self.device, self.steps = cfg, device, steps
        self.model = build_model(cfg, seed).to(device)
        # a pretrained layer being fine-tuned (minilm-tuned) gets its own, lower peak lr
        named = list(self.model.named_parameters())
        groups = [{"params": [p for n, p in named if not n.startswith("lang.layer.")], "lr": lr}]
        tuned = [p for n, p in named if n.startswith("lang.layer.")]
        if tuned:
            groups.append({"params": tuned, "lr": lr_tuned})
        self.opt = torch.optim.AdamW(groups, lr=lr, weight_decay=weight_decay)
        self.sched = torch.optim.lr_scheduler.OneCycleLR(self.opt, max_lr=[g["lr"] for g in groups],
                                                         total_steps=max(steps, 2), pct_start=0.05)
        self.step = 0

    def to_device(self, batch: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
        out = {k: torch.from_numpy(np.ascontiguousarray(v)).to(self.device, non_blocking=True)
               for k, v in batch.items()}
        if out["bev"].dtype == torch.uint8:
            out["bev"] = unpack_bev(out["bev"])
        return out

    def train_step(self, batch: dict[str, torch.Tensor]) -> dict[str, float]:
        self.model.train()
        out = self.model(batch["bev"], batch["ids"], batch["speed"], batch["stopped_for"])
        loss = losses(out, batch)
        self.opt.zero_grad(set_to_none=True)
        loss["total"].backward()
        nn.utils.clip_grad_norm_(self.model.parameters(), 5.0)
        self.opt.step()
        if self.step < self.steps - 1:
            self.sched.step()
        self.step += 1
        return {k: float(v.detach()) for k, v in loss.items()}

    @torch.no_grad()
    def evaluate(self, batch: dict[str, torch.Tensor]) -> dict[str, float]:
        self.model.eval()
        out = self.model(batch["bev"], batch["ids"], batch["speed"], batch["stopped_for"])
        loss = losses(out, batch)
        res = {k: float(v) for k, v in loss.items()}
        stop_true = batch["target_speed"] < STOP_BELOW
        res["stop_acc"] = float(((out["stop"] > 0) == stop_true).float().mean())
        res["intent_acc"] = float((out["intent"].argmax(1) == batch["intent"]).float().mean())
        res["final_wp_err"] = float((out["waypoints"][:, -1] - batch["waypoints"][:, -1]).norm(dim=-1).mean())
        return res

    def state(self, extra: dict) -> dict:
        return {"format": STATE_FORMAT, "config": _cfg_dict(self.cfg), "step": self.step,
                "model": self.model.state_dict(), "opt": self.opt.state_dict(),
                "sched": self.sched.state_dict(), **extra}

    def load_state(self, state: dict, path: Path | str = "checkpoint") -> None:
        """Resume from :meth:`state` (read from ``path``); a state that does not fit this
        trainer (format, model config, weights, optimizer, step) is an InputError naming
        ``path`` (the trainer is not to be used then)."""
        fix = _RESUME_FIX
        if state.get("format") != STATE_FORMAT:
            raise InputError(path, "format", f"not an icrsumo training checkpoint (format "
                             f"{_short(state.get('format'))})", fix)
        if state.get("config") != _cfg_dict(self.cfg):
            raise InputError(path, "config", "holds another model configuration", fix)
        check_weights(state.get("model"), self.cfg, path, "model", fix)
        step = expect(state.get("step"), int, path, "step", "the step", fix)
        if not 0 <= step <= self.steps:
            raise InputError(path, "step", f"step {step} is outside 0..{self.steps}", fix)
        opt = expect(state.get("opt"), dict, path, "opt", "the optimizer state", fix)
        sched = expect(state.get("sched"), dict, path, "sched", "the schedule state", fix)
        params = list(self.model.parameters())
        per_param = opt.get("state", {})
        expect(per_param, dict, path, "opt.state", "the optimizer state", fix)
        for i, st in per_param.items():
            if not isinstance(i, int) or not 0 <= i < len(params) or not isinstance(st, dict):
                raise InputError(path, f"opt.state[{i!r}]", "does not fit the model's parameters", fix)
            for k, v in st.items():
                if k in ("exp_avg", "exp_avg_sq") and (not isinstance(v, torch.Tensor)
                                                       or v.shape != params[i].shape):
                    raise InputError(path, f"opt.state[{i}].{k}", "does not fit the model's parameters", fix)
        try:
            self.model.load_state_dict(state["model"])
            self.opt.load_state_dict(opt)
            self.sched.load_state_dict(sched)
            self.sched.get_last_lr()
        except (KeyError, ValueError, TypeError, RuntimeError, IndexError, AttributeError) as err:
            raise InputError(path, "opt/sched", f"optimizer state does not fit ({_first_line(err)})",
                             fix) from None
        self.step = step


_RESUME_FIX = f"delete it to start over, or use another {Field('out')} folder"


def _first_line(err: BaseException) -> str:
    """The first sentence of an exception's message, without terminal escapes, for one line."""
    text = re.sub(r"\x1b\[[0-9;]*m", "", str(err)).strip()
    text = (text.splitlines() or [""])[0].split(". ")[0].strip()
    text = text[:160] + ("..." if len(text) > 160 else "")
    return f"{type(err).__name__}: {text}" if text else type(err).__name__


def check_weights(weights: object, cfg: ModelConfig, path: Path | str = "checkpoint", place: str = "model",
                  fix: str = _CHECKPOINT_FIX) -> dict:
    """``weights`` if they are a state dict of :class:`BevLanguageNet` with ``cfg`` (the same
    names, shapes and floating-point tensors); an InputError naming ``path`` otherwise. The
    expected shapes come from a model on the ``meta`` device: nothing is allocated."""
    weights = expect(weights, dict, path, place, "the weights", fix)
    with torch.device("meta"):
        want = {k: tuple(v.shape) for k, v in BevLanguageNet(cfg).state_dict().items()}
    missing = [k for k in want if k not in weights]
    extra = [str(k) for k in weights if k not in want]
    if missing or extra:
        parts = ([f"{len(missing)} missing (e.g. {missing[0]})"] if missing else []) + (
            [f"{len(extra)} unexpected (e.g. {extra[0]})"] if extra else [])
        raise InputError(path, place, f"weights do not fit the model config: {', '.join(parts)}", fix)
    for k, shape in want.items():
        t = weights[k]
        if not isinstance(t, torch.Tensor) or not t.is_floating_point():
            kind = f"tensor of {t.dtype}" if isinstance(t, torch.Tensor) else type(t).__name__
            raise InputError(path, f"{place}.{k}", f"is a {kind}, not a floating-point tensor", fix)
        if tuple(t.shape) != shape:
            raise InputError(path, f"{place}.{k}", f"shape {tuple(t.shape)} does not fit the model "
                             f"config's {shape}", fix)
    return weights


def save(obj: dict, path: Path) -> None:
    """Write ``obj`` with torch.save atomically (temporary file, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    torch.save(obj, tmp)
    tmp.replace(path)


def load(path: Path, what: str = "checkpoint", fix: str = _CHECKPOINT_FIX) -> dict:
    """Read a checkpoint dict with ``weights_only=True`` (no code runs from the file). A file
    that is missing, empty, truncated, not a torch file, refused by the safe loader or not a
    dict is an InputError naming it (``what`` names the file in the message)."""
    path = Path(path)
    if path.is_dir():
        raise InputError(path, "", f"is a folder, not a file ({what})", "pass the .pt file")
    try:
        if path.stat().st_size == 0:
            raise InputError(path, "", f"{what} is empty (0 bytes)", fix)
        obj = torch.load(path, map_location="cpu", weights_only=True)
    except InputError:
        raise
    except (FileNotFoundError, PermissionError) as err:
        raise unreadable(path, what, "check the path", err) from None
    except pickle.UnpicklingError as err:
        if "Weights only load failed" not in str(err):
            raise InputError(path, "", f"{what} is damaged, not a torch file ({_first_line(err)})",
                             fix) from None
        m = re.search(r"GLOBAL ([\w.]+)", str(err))
        held = f" ({m.group(1)})" if m else ""
        raise InputError(path, "", f"{what} refused by torch.load(weights_only=True): it holds a pickled "
                         f"Python object{held}, not only tensors, numbers and strings", "never load an "
                         "untrusted pickle; " + fix) from None
    except EOFError:
        raise InputError(path, "", f"{what} is truncated", fix) from None
    except MemoryError:
        raise
    except Exception as err:  # torch's reader: truncated zip archive, not a torch file, ...
        raise InputError(path, "", f"{what} is truncated or not a torch file ({_first_line(err)})",
                         fix) from None
    if not isinstance(obj, dict):
        raise InputError(path, "", f"{what} holds a {type(obj).__name__}, not an icrsumo checkpoint", fix)
    return obj


def read_checkpoint(path: Path) -> tuple[dict, ModelConfig]:
    """An inference checkpoint (:func:`export`) and its model config, checked: its format, its
    config and that its weights fit that config; problems are InputErrors naming ``path``."""
    ck = load(path, "agent checkpoint")
    fmt = ck.get("format")
    if fmt != CHECKPOINT_FORMAT:
        hint = " (a training state: use the model.pt beside it)" if fmt == STATE_FORMAT else ""
        raise InputError(path, "format", f"not an icrsumo agent checkpoint (format {_short(fmt)}){hint}",
                         _CHECKPOINT_FIX)
    cfg = config_from_dict(ck.get("config"), path)
    check_weights(ck.get("model"), cfg, path)
    return ck, cfg


def export(trainer: Trainer, path: Path, meta: dict) -> None:
    """The inference checkpoint: format, config, float32 weights and ``meta`` (data, steps)."""
    weights = {k: v.detach().to("cpu", torch.float32) if v.is_floating_point() else v.detach().cpu()
               for k, v in trainer.model.state_dict().items()}
    save({"format": CHECKPOINT_FORMAT, "config": _cfg_dict(trainer.cfg), "model": weights,
          "meta": meta}, path)


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

    from .runtime import INPUTS, OUTPUTS

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
            from .runtime import OrtFuse

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


def parameter_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())

