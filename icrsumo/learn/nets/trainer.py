"""Training of the learned agents' models (:mod:`icrsumo.learn.nets`): :class:`Trainer`, one
optimisation step at a time, its whole state saved and resumed (:mod:`icrsumo.learn.train`
drives it)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from icrsumo.core.errors import Field, InputError, expect

from ..config import ModelConfig
from ..config import config_dict as _cfg_dict
from ..config import short_repr as _short
from ..labels import STOP_BELOW
from .checkpoint import STATE_FORMAT, check_weights, error_line
from .models import build_model, losses, unpack_bev

_RESUME_FIX = f"delete it to start over, or use another {Field('out')} folder"


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
            raise InputError(path, "opt/sched", f"optimizer state does not fit ({error_line(err)})",
                             fix) from None
        self.step = step
