"""``icrsumo export-exact``: a float checkpoint (``model.pt`` of ``icrsumo train``) made exact.

Post-training quantisation, calibrated on recorded observations (``icrsumo collect`` folders):
weights to int8 per output channel (symmetric, scale ``max|w| / 127``), activations to 0..255
after each ReLU and the language vector to -127..127, each with one scale from the float
network's activations on the calibration frames (their ``percentile``-th percentile), biases
to integers in the accumulator's units. Then every product's worst partial sum is checked
against 2**24 (:func:`icrsumo.learn.exact.checkpoint.bounds`): a layer that could leave
float32's exact integers, or a layer the exact graph does not have, is an InputError naming it,
and nothing is written. Needs torch (to read the float checkpoint and run it).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from icrsumo.core.errors import InputError

from ..labels import ARC_M
from .checkpoint import SUFFIX, ExactCheckpoint, bounds, check_arrays, layout, save
from .graph import EXACT_LIMIT, HIDDEN_BITS, LMAX, SMAX, TABLE_HALF, TABLE_STEP, UMAX


class _NotExact(Exception):
    """A layer that cannot be made exact: ``args`` = (its name, why); :func:`export_exact`
    names the checkpoint."""


def _per_channel(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``w`` (out, in) float -> int8 ``(in, out)`` and the per-output-channel scales (out,)."""
    w = np.asarray(w, np.float64)
    scale = np.abs(w).max(1) / SMAX
    scale[scale == 0] = 1.0
    return np.clip(np.rint(w / scale[:, None]), -SMAX, SMAX).astype(np.int8).T.copy(), scale


def _bias(b: np.ndarray, unit: np.ndarray, name: str) -> np.ndarray:
    """A float bias in accumulator units ``unit`` (per channel) as int32 (it must stay below
    2**24 to be carried exactly)."""
    v = np.rint(np.asarray(b, np.float64) / unit)
    if not np.all(np.abs(v) < EXACT_LIMIT):
        raise _NotExact(name, "its bias is 2**24 or more accumulator units")
    return v.astype(np.int32)


def _dense(out: dict, name: str, w: np.ndarray, b: np.ndarray, s_in: float,
           s_out: float | None) -> np.ndarray:
    """A product layer: int8 weights, int32 bias, and the requantisation multiplier
    ``{name}.m`` = s_in * s_w / s_out (when ``s_out``); returns the accumulator units."""
    wq, sw = _per_channel(w)
    unit = s_in * sw
    out[f"{name}.w"], out[f"{name}.b"] = wq, _bias(b, unit, name)
    if s_out is not None:
        out[f"{name}.m"] = (unit / s_out).astype(np.float32)
    return unit


def _conv_rows(w: np.ndarray) -> np.ndarray:
    """A torch conv weight (out, in, kh, kw) as (out, kh*kw*in): the im2col column order."""
    return np.asarray(w).transpose(0, 2, 3, 1).reshape(w.shape[0], -1)


def _scale(values: np.ndarray, percentile: float, top: int) -> float:
    """The scale that maps the ``percentile``-th percentile of ``|values|`` to ``top``."""
    return _range(values, percentile) / top


def _range(values: np.ndarray, percentile: float) -> float:
    """The ``percentile``-th percentile of ``|values|`` (1 when it is 0)."""
    v = np.abs(np.asarray(values, np.float64).reshape(-1))
    hi = float(np.percentile(v, percentile)) if v.size else 0.0
    return hi if hi > 0 else 1.0


def _top(name: str, w: np.ndarray, b: np.ndarray, rng: float) -> int:
    """The largest input top (at most UMAX) for which product ``name`` (float weights ``w``
    (out, in), bias ``b``, input range ``rng``) stays below 2**24 (at least 15)."""
    wq, sw = _per_channel(w)
    l1 = np.abs(wq.astype(np.int64)).sum(0)
    for top in range(UMAX, 14, -1):
        bq = np.abs(np.rint(np.asarray(b, np.float64) / (rng / top * sw)))
        if float((top * l1 + bq).max()) < EXACT_LIMIT:
            return top
    raise _NotExact(name, "even 4-bit activations let its partial sums reach 2**24 (weights too wide)")


def calibration_frames(folders: list[Path], limit: int = 4000, seed: int = 0):
    """Up to ``limit`` frames of ``icrsumo collect`` folders (evenly spaced): ``bev`` (N, 7,
    H, W) uint8 0/255, ``texts`` (N,), ``speed`` and ``stopped`` (N,) float32."""
    from ..collect import read_episode

    files = sorted(p for f in folders for p in Path(f).glob("episodes/*.npz"))
    if not files:
        raise InputError(folders[0] if folders else "calibration", "", "no collected episodes found",
                         "give a folder written by icrsumo collect")
    bevs, texts, speed, stopped = [], [], [], []
    for p in files:
        arr, docs = read_episode(p, ("bev", "speed", "instruction", "stopped_for"))
        bevs.append(arr["bev"])
        texts += [docs[i]["text"] if i >= 0 else "" for i in arr["instruction"]]
        speed.append(arr["speed"])
        stopped.append(arr["stopped_for"])
    packed = np.concatenate(bevs)
    idx = np.unique(np.linspace(0, len(packed) - 1, min(limit, len(packed))).astype(np.int64))
    bev = np.unpackbits(packed[idx], axis=-1) * np.uint8(255)
    return (bev, [texts[i] for i in idx], np.concatenate(speed)[idx].astype(np.float32),
            np.concatenate(stopped)[idx].astype(np.float32))


def augmented_texts(folders: list[Path], variants: int = 8, seed: int = 0) -> list[str]:
    """``variants`` training-bank paraphrases and noisy variants (:func:`icrsumo.learn.augment.
    augment`) of every instruction the ``icrsumo collect`` folders hold: the language side's
    calibration texts (no evaluation bank is read)."""
    from ..augment import augment, load_train_bank
    from ..collect import read_episode

    docs: dict[str, dict] = {}
    for p in sorted(p for f in folders for p in Path(f).glob("episodes/*.npz")):
        docs.update({json.dumps(d, sort_keys=True): d for d in read_episode(p, ("instruction",))[1]})
    rng, bank = np.random.default_rng(seed), load_train_bank()
    return [augment(d, rng, bank=bank) for _, d in sorted(docs.items()) for _ in range(variants)]


def export_exact(checkpoint: Path, frames, extra_texts: list[str] = (), percentile: float = 99.99,
                 meta: dict | None = None) -> ExactCheckpoint:
    """The exact checkpoint of float ``checkpoint``, calibrated on ``frames`` (as
    :func:`calibration_frames` returns) and the language side also on ``extra_texts``. A
    checkpoint that cannot be made exact is an InputError naming it and the layer."""
    from .. import nets

    ck, cfg = nets.read_checkpoint(Path(checkpoint))
    if cfg.encoder not in ("ngram", "token", "minilm"):
        raise InputError(checkpoint, "config.encoder", f"encoder {cfg.encoder!r} has no exact form (its "
                         "fine-tuned transformer layer)", "export a token, ngram or minilm checkpoint")
    try:
        a = _quantize(ck, cfg, frames, extra_texts, percentile)
    except _NotExact as err:
        raise InputError(checkpoint, err.args[0], f"cannot be made exact: {err.args[1]}",
                         "retrain with weight decay, or a narrower layer") from None
    bev, texts = frames[0], frames[1]
    info = {"source": Path(checkpoint).name, "source_meta": ck.get("meta", {}), "percentile": percentile,
            "calibration_frames": len(bev), "calibration_texts": len(dict.fromkeys([*texts, *extra_texts])),
            "bounds": bounds(a), **(meta or {})}
    check_arrays(a, cfg, checkpoint)
    return ExactCheckpoint(config=cfg, arrays=a, meta=json.loads(json.dumps(info, default=str)))


def _quantize(ck: dict, cfg, frames, extra_texts, percentile: float) -> dict[str, np.ndarray]:
    """The arrays of :func:`icrsumo.learn.exact.checkpoint.layout` for float checkpoint ``ck``."""
    import torch

    from .. import nets

    state = {k: v.detach().double().numpy() for k, v in ck["model"].items()}
    net = nets.BevLanguageNet(cfg)
    net.load_state_dict(ck["model"])
    net.eval()
    bev, texts, speed, stopped = frames
    all_texts = list(dict.fromkeys([*texts, *extra_texts]))
    enc = cfg.text_encoder()
    a: dict[str, np.ndarray] = {}
    with torch.no_grad():
        ids = torch.from_numpy(enc.encode_many(all_texts))
        lang_f = net.lang(ids).double().numpy()                       # (T, lang)
        s_l = _scale(lang_f, 100.0, LMAX)
        _language(a, cfg, state, net, ids, s_l, percentile)
        # the driving network's activations on the calibration frames (in chunks)
        acts: dict[str, list[np.ndarray]] = {k: [] for k in ("s1", "s2", "s3", "s4", "s5", "s6", "s7")}
        row = {t: i for i, t in enumerate(all_texts)}
        for i in range(0, len(bev), 256):
            x = torch.from_numpy(bev[i:i + 256]).double() / 255.0
            lang = torch.from_numpy(lang_f[[row[t] for t in texts[i:i + 256]]])
            sp = torch.from_numpy(speed[i:i + 256]).double()
            st = torch.from_numpy(stopped[i:i + 256]).double()
            taps: list = []
            net.double().fuse(x, lang, sp, st, taps=taps)
            for key, v in zip(acts, taps):
                acts[key].append(v.numpy().reshape(-1)[:: max(1, v[0].numel() // 4096)])
        net.float()
    r = {k: _range(np.concatenate(v), percentile) for k, v in acts.items()}
    w, hid, lang = cfg.width, cfg.hidden, cfg.lang
    w0 = state["mlp.0.weight"]
    # torch flattens (C, 4, 4) before fc; the exact graph's rows are NHWC: (h, w, c)
    fc = state["fc.weight"].reshape(-1, 4 * w, 4, 4).transpose(0, 2, 3, 1).reshape(hid, -1)
    # the stem's patches are (c, kh, kw) (graph.patches4), the 3x3 convolutions' (kh, kw, c)
    layers = {"stem": (state["stem.weight"].reshape(w, -1), state["stem.bias"]),
              "c2": (_conv_rows(state["c2.weight"]), state["c2.bias"]),
              "c3": (_conv_rows(state["c3.weight"]), state["c3.bias"]),
              "c4": (_conv_rows(state["c4.weight"]), state["c4.bias"]),
              "fc": (fc, state["fc.bias"]), "mlp0": (w0[:, :hid], np.zeros(hid)),
              "mlp1": (state["mlp.2.weight"], state["mlp.2.bias"]),
              "head": (state["head.weight"], state["head.bias"])}
    # the scale of each product's input: the activation's range over the top the product allows
    s_in = {"stem": 1.0 / 255.0}
    for name, key in zip(list(layers)[1:], r):
        a[f"{name}.top"] = np.array(_top(name, *layers[name], r[key]), np.int32)
        s_in[name] = r[key] / int(a[f"{name}.top"])
    nxt = dict(zip(layers, [*list(layers)[1:], None]))
    for name in ("stem", "c2", "c4", "fc", "mlp1"):
        _dense(a, name, *layers[name], s_in[name], s_in[nxt[name]])
    unit3 = _dense(a, "c3", *layers["c3"], s_in["c3"], None)
    a["c3.k"], a["c3.inv"] = unit3 / s_in["c4"], np.full(4 * w, 1.0 / s_in["c4"])
    a["film.k"] = _dense(a, "film", state["film.weight"], state["film.bias"], s_l, None)
    a["mlp0.k"] = _dense(a, "mlp0", *layers["mlp0"], s_in["mlp0"], None).astype(np.float32)
    wl, swl = _per_channel(w0[:, hid:hid + lang])
    a["mlp0.wl"], a["mlp0.kl"], a["mlp0.bias"] = wl, s_l * swl, state["mlp.0.bias"].copy()
    a["mlp0.wsp"] = w0[:, hid + lang].astype(np.float32)
    a["mlp0.wst"] = w0[:, hid + lang + 1].astype(np.float32)
    a["mlp0.m"] = np.full(hid, 1.0 / s_in["mlp1"], np.float32)
    a["head.d"] = _dense(a, "head", *layers["head"], s_in["head"], None).astype(np.float32)
    a["arc"] = np.asarray(ARC_M, np.float32)
    dtypes = {k: dtype for k, (_, dtype) in layout(cfg).items()}
    a = {k: v.astype(dtypes[k]) for k, v in a.items()}
    for name, bound in bounds(a).items():
        if bound >= EXACT_LIMIT:
            raise _NotExact(name, f"its partial sums can reach {bound} >= 2**24 (weights too wide for "
                            "8-bit activations)")
    return a


def _language(a: dict, cfg, state: dict, net, ids, s_l: float, percentile: float) -> None:
    """The language encoder's arrays (ngram / minilm: input scale, two layers; token: the GRU
    with its tables) for language vector scale ``s_l``."""
    import torch

    if cfg.encoder == "token":
        emb = state["lang.emb.weight"]
        s_e = float(np.abs(emb).max()) / SMAX or 1.0
        a["lang.emb"] = np.clip(np.rint(emb / s_e), -SMAX, SMAX).astype(np.int8)
        h_unit = 2.0 ** -HIDDEN_BITS
        for d, suffix in (("f", ""), ("r", "_reverse")):
            wi, swi = _per_channel(state[f"lang.gru.weight_ih_l0{suffix}"])
            wh, swh = _per_channel(state[f"lang.gru.weight_hh_l0{suffix}"])
            a[f"gru.{d}.wih"], a[f"gru.{d}.kih"] = wi, s_e * swi
            a[f"gru.{d}.whh"], a[f"gru.{d}.khh"] = wh, h_unit * swh
            a[f"gru.{d}.bih"] = state[f"lang.gru.bias_ih_l0{suffix}"].copy()
            a[f"gru.{d}.bhh"] = state[f"lang.gru.bias_hh_l0{suffix}"].copy()
        grid = np.arange(-TABLE_HALF, TABLE_HALF + 1, dtype=np.float64) / TABLE_STEP
        a["gru.sigmoid"] = np.array([1.0 / (1.0 + math.exp(-v)) for v in grid])
        a["gru.tanh"] = np.array([math.tanh(v) for v in grid])
        a["lang.out_m"] = np.full(cfg.lang, h_unit / s_l, np.float32)
        return
    with torch.no_grad():
        lang = net.lang.double()
        if cfg.encoder == "ngram":
            emb = state["lang.emb.weight"]
            s_e = float(np.abs(emb).max()) / SMAX or 1.0
            a["lang.emb"] = np.clip(np.rint(emb / s_e), -SMAX, SMAX).astype(np.int8)
            mask = (ids > 0).unsqueeze(-1).double()
            x = (lang.emb(ids) * mask).sum(1) / mask.sum(1).clamp(min=1.0)
            s_in = _scale(x.numpy(), 100.0, SMAX)
            a["lang.emb_m"] = np.full(cfg.embed, s_e / s_in, np.float32)
        else:
            x = ids.double()
            s_in = _scale(x.numpy(), 100.0, SMAX)
            a["lang.in_m"] = np.full(cfg.text_len, 1.0 / s_in, np.float32)
        h1 = torch.relu(lang.mlp[0](x))
        r_h1 = _range(h1.numpy(), percentile)
        net.float()
    a["lang.l2.top"] = np.array(_top("lang.l2", state["lang.mlp.2.weight"], state["lang.mlp.2.bias"], r_h1),
                                np.int32)
    s_h1 = r_h1 / int(a["lang.l2.top"])
    _dense(a, "lang.l1", state["lang.mlp.0.weight"], state["lang.mlp.0.bias"], s_in, s_h1)
    _dense(a, "lang.l2", state["lang.mlp.2.weight"], state["lang.mlp.2.bias"], s_h1, s_l)


def export_file(checkpoint: Path, out: Path, calibration: list[Path], frames: int = 4000,
                percentile: float = 99.99) -> ExactCheckpoint:
    """``icrsumo export-exact``: calibrate on up to ``frames`` frames of the ``calibration``
    folders (``icrsumo collect`` output) and the training bank's phrasings, check, and write
    ``out`` (``.npz``); nothing is written when any check fails."""
    out = Path(out)
    if out.suffix != SUFFIX:
        raise InputError(out, "", f"an exact checkpoint's name ends in {SUFFIX}",
                         f"name it {out.stem}{SUFFIX}")
    if not 50.0 < percentile <= 100.0:
        raise InputError("percentile", "", f"{percentile} is not in (50, 100]",
                         "use 99.99 (the default) or 100")
    folders = [Path(c) for c in calibration]
    data = calibration_frames(folders, limit=frames)
    ck = export_exact(Path(checkpoint), data, extra_texts=augmented_texts(folders), percentile=percentile,
                      meta={"calibration": [Path(c).name for c in calibration]})
    save(ck, out)
    return ck
