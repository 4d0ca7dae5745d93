"""Torch models of the learned agents, their float checkpoints, training and inference.

* :mod:`~icrsumo.learn.nets.models`: the model (``BevLanguageNet``: a small CNN on the BEV
  raster, a language encoder ``token``, ``ngram``, ``minilm`` or ``minilm-tuned``, FiLM
  fusion, waypoint / speed / stop / intent heads), its losses and the device it runs on;
* :mod:`~icrsumo.learn.nets.checkpoint`: float checkpoints (``.pt``) written and read safely
  (``torch.load(..., weights_only=True)``), every problem an InputError naming the file;
* :mod:`~icrsumo.learn.nets.trainer`: :class:`Trainer`, one training step at a time;
* :mod:`~icrsumo.learn.nets.policy`: :class:`Policy`, inference of a float checkpoint, and the
  in-memory ONNX export.

Every public name of the four is importable from here, as it was from the single module before.
"""

from __future__ import annotations

from ..config import MINILM_SHAPE, ModelConfig, config_from_dict
from .checkpoint import CHECKPOINT_FORMAT, STATE_FORMAT, check_weights, export, load, read_checkpoint, save
from .models import (
    BERT_PARTS,
    INTENTS,
    BertLayer,
    BevLanguageNet,
    bert_layer_state,
    build_model,
    losses,
    parameter_count,
    pick_device,
    sentence_embedding,
    unpack_bev,
)
from .policy import GPU_BATCH, RUNTIMES, Policy, onnx_bytes
from .trainer import Trainer

__all__ = [
    "BERT_PARTS", "CHECKPOINT_FORMAT", "GPU_BATCH", "INTENTS", "MINILM_SHAPE", "RUNTIMES", "STATE_FORMAT",
    "BertLayer", "BevLanguageNet", "ModelConfig", "Policy", "Trainer", "bert_layer_state", "build_model",
    "check_weights", "config_from_dict", "export", "load", "losses", "onnx_bytes", "parameter_count",
    "pick_device", "read_checkpoint", "save", "sentence_embedding", "unpack_bev",
]
