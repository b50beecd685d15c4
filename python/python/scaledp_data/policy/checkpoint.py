"""The project's checkpoint format, read and written from Python (``policy/src/checkpoint.rs``):

- ``checkpoints/step_<8 digits>/model.safetensors``: the EMA weights under the state-dict names
  (what ``scaledp serve`` / ``eval`` / ``predict`` load);
- ``train_state.safetensors``: the raw weights (``params.<name>``) and AdamW's moments
  (``optim.<name>.exp_avg``, ``optim.<name>.exp_avg_sq``);
- ``config.json``: model, schedule, normalizer, names, fps, provenance, step, seed, the loader's
  position (global: samples of the epoch every rank has consumed together) and the training
  options, plus the image chain.

A directory is written under a temporary name and renamed when complete, as the Rust trainer
does, so a killed run never leaves a half-written checkpoint under its final name.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from typing import Any, Dict, List, Optional, Tuple

import torch

from .options import DPT_DIMS, DPT_DROPOUT, MODEL_SIZES

__all__ = ["FORMAT", "VERSION", "model_config", "checkpoint_config", "write", "list_checkpoints",
           "resolve", "read_config", "read_train_state"]

FORMAT = "scaledp-policy"
VERSION = 1
MODEL_FILE = "model.safetensors"
TRAIN_STATE_FILE = "train_state.safetensors"
CONFIG_FILE = "config.json"


def model_config(info: Dict[str, Any], o: Dict[str, Any]) -> Dict[str, Any]:
    """The ``ModelConfig`` a run with options ``o`` gets on a loader whose ``info`` this is."""
    arch = o.get("arch", "scale_dp")
    if arch == "dp_t":
        size: Optional[str] = None
        (depth, hidden, heads), dropout = DPT_DIMS, DPT_DROPOUT
    else:
        size = o["size"]
        (depth, hidden, heads), dropout = MODEL_SIZES[o["size"]], 0.0
    if o.get("dropout") is not None:
        dropout = float(o["dropout"])
    if o.get("denoiser"):
        size, (depth, hidden, heads) = None, o["denoiser"]
    w, h = info["image_size"]
    m = {
        "size": size, "depth": depth, "hidden": hidden, "heads": heads, "mlp_ratio": 4,
        "obs_horizon": o["obs_horizon"], "action_chunk": o["action_chunk"],
        "state_dim": len(info["state_names"]), "action_dim": len(info["action_names"]),
        "cameras": list(info["cameras"]), "image_width": w, "image_height": h,
        "crop": o["crop"], "resnet_width": o["resnet_width"], "keypoints": 32,
        "feature_dim": 64, "image_range": o["image_range"], "attention": o["attention"],
        "arch": arch, "dropout": dropout, "pos_embed": o.get("pos_embed", "learned"),
    }
    validate_model(m)
    return m


def validate_model(m: Dict[str, Any]) -> None:
    """``ModelConfig::validate``: raises ValueError when the numbers do not fit together."""
    from .model import camera_short_name, crop_size

    if m["depth"] < 1 or m["hidden"] < 1 or m["heads"] < 1 or m["hidden"] % m["heads"]:
        raise ValueError(f"hidden width {m['hidden']} must be a positive multiple of the "
                         f"{m['heads']} heads (depth {m['depth']})")
    if min(m["obs_horizon"], m["action_chunk"], m["action_dim"]) < 1:
        raise ValueError("obs_horizon, action_chunk and the action width must be at least 1")
    if m.get("pos_embed", "learned") == "sin_cos":
        if m.get("arch") == "dp_t":
            raise ValueError("a fixed sin-cos pos_embed is a ScaleDP option; DP-T learns its own")
        if m["hidden"] % 2:
            raise ValueError(f"a sin-cos pos_embed needs an even width, not {m['hidden']}")
    if not 0.0 <= m.get("dropout", 0.0) < 1.0:
        raise ValueError(f"dropout {m['dropout']} outside [0, 1)")
    if not 0.0 < m["crop"] <= 1.0:
        raise ValueError(f"crop ratio {m['crop']} outside (0, 1]")
    if m["cameras"]:
        cw, ch = crop_size(m)
        if cw < 8 or ch < 8:
            raise ValueError(f"images of {m['image_width']}x{m['image_height']} cropped to "
                             f"{cw}x{ch}: the ResNet trunk needs at least 8x8")
    if len({camera_short_name(c) for c in m["cameras"]}) != len(m["cameras"]):
        raise ValueError(f"cameras {m['cameras']} share a weight prefix")


def _provenance(dataset: str) -> Dict[str, Any]:
    """What a local dataset's ``meta/info.json`` says about where it came from."""
    try:
        with open(os.path.join(dataset, "meta", "info.json")) as f:
            v = json.load(f)
    except (OSError, ValueError):
        return {}
    sd = v.get("scaledp") or {}
    text = lambda x: x if isinstance(x, str) and x else None  # noqa: E731
    size = sd.get("image_size")
    stored = {}
    for key, feat in (v.get("features") or {}).items():
        shape, names = feat.get("shape"), feat.get("names")
        if not isinstance(shape, list) or len(shape) != 3:
            continue
        if isinstance(names, list) and "height" in names and "width" in names:
            hw = (shape[names.index("height")], shape[names.index("width")])
        elif shape[2] in (1, 3, 4):
            hw = (shape[0], shape[1])
        elif shape[0] in (1, 3, 4):
            hw = (shape[1], shape[2])
        else:
            continue
        stored[key] = (int(hw[1]), int(hw[0]))
    converted = None
    if isinstance(size, list) and len(size) >= 2:
        converted = ((int(size[0]), int(size[1])), sd.get("jpeg_quality"))
    return {"robot_type": text(v.get("robot_type")), "rig": text(sd.get("rig")),
            "converted": converted, "stored": stored}


def _image_chain(p: Dict[str, Any], m: Dict[str, Any]) -> Dict[str, Any]:
    """Camera frame -> encoder input of a run at the model's input size."""
    inp = (m["image_width"], m["image_height"])
    conv = p.get("converted")
    stored = p.get("stored", {}).get(m["cameras"][0]) or (conv[0] if conv else None) or inp
    made_by, quality = ("scaledp-convert", conv[1]) if conv and conv[0] == stored else ("unknown", None)
    return {
        "stored": {"width": stored[0], "height": stored[1], "made_by": made_by,
                   "jpeg_quality": quality},
        "train_resize": None if stored == inp else {"width": inp[0], "height": inp[1],
                                                    "filter": "bilinear"},
        "crop": m["crop"], "range": m["image_range"],
    }


def checkpoint_config(dataset: str, info: Dict[str, Any], normalizer: Any,
                      o: Dict[str, Any]) -> Dict[str, Any]:
    """``config.json`` of a new run (``step``, ``loader`` and ``train`` are filled at each save).
    ``normalizer`` is the loader's :class:`scaledp_data.Normalizer`."""
    m = model_config(info, o)
    prov = _provenance(dataset)

    def norm(kind: str) -> Dict[str, Any]:
        return {"norm": getattr(normalizer, f"{kind}_norm"),
                "scale": list(getattr(normalizer, f"{kind}_scale")),
                "offset": list(getattr(normalizer, f"{kind}_offset"))}

    cfg = {
        "format": FORMAT, "version": VERSION, "model": m,
        "diffusion": {"train_steps": 100, "inference_steps": 10},
        "normalizer": {"state": norm("state"), "action": norm("action")},
        "state_names": list(info["state_names"]), "action_names": list(info["action_names"]),
        "fps": float(info["fps"]), "robot_type": prov.get("robot_type"), "rig": prov.get("rig"),
        "dataset": dataset, "step": 0, "seed": o["seed"], "loader": None, "train": None,
    }
    if m["cameras"]:
        cfg["images"] = _image_chain(prov, m)
    return cfg


def dir_name(step: int) -> str:
    """The directory of the checkpoint after ``step`` steps."""
    return f"step_{step:08d}"


def write(run: str, step: int, cfg: Dict[str, Any], ema: Dict[str, torch.Tensor],
          params: Dict[str, torch.Tensor], moments: Dict[str, Tuple[torch.Tensor, torch.Tensor]]) -> str:
    """Writes ``run/checkpoints/step_N`` (under a temporary name first) and returns it."""
    from safetensors.torch import save_file

    root = os.path.join(run, "checkpoints")
    name = dir_name(step)
    tmp, final = os.path.join(root, f".{name}.partial"), os.path.join(root, name)
    shutil.rmtree(tmp, ignore_errors=True)
    os.makedirs(tmp)
    cpu = lambda t: t.detach().to("cpu", torch.float32).contiguous()  # noqa: E731
    save_file({k: cpu(v) for k, v in ema.items()}, os.path.join(tmp, MODEL_FILE))
    state = {f"params.{k}": cpu(v) for k, v in params.items()}
    for k, (m, v) in moments.items():
        state[f"optim.{k}.exp_avg"] = cpu(m)
        state[f"optim.{k}.exp_avg_sq"] = cpu(v)
    save_file(state, os.path.join(tmp, TRAIN_STATE_FILE))
    with open(os.path.join(tmp, CONFIG_FILE), "w") as f:
        json.dump(cfg, f, indent=2)
    shutil.rmtree(final, ignore_errors=True)
    os.rename(tmp, final)
    return final


def list_checkpoints(run: str) -> List[Tuple[int, str]]:
    """``run/checkpoints/step_*`` holding a ``config.json``, by step, ascending."""
    root = os.path.join(run, "checkpoints")
    out = []
    for name in os.listdir(root) if os.path.isdir(root) else []:
        m = re.fullmatch(r"step_(\d+)", name)
        if m and os.path.exists(os.path.join(root, name, CONFIG_FILE)):
            out.append((int(m.group(1)), os.path.join(root, name)))
    return sorted(out)


def resolve(path: str) -> str:
    """A checkpoint directory from what a user names: itself, or a run's latest checkpoint."""
    if os.path.exists(os.path.join(path, CONFIG_FILE)):
        return path
    found = list_checkpoints(path)
    if not found:
        raise FileNotFoundError(f"{path}: neither a checkpoint ({CONFIG_FILE}) nor a run with "
                                "checkpoints/step_*")
    return found[-1][1]


def read_config(ckpt: str) -> Dict[str, Any]:
    """``ckpt/config.json``, checked for its format and version (fields written before they
    existed take the values those checkpoints meant)."""
    path = os.path.join(ckpt, CONFIG_FILE)
    with open(path) as f:
        cfg = json.load(f)
    if isinstance(cfg.get("model"), dict):
        cfg["model"].setdefault("arch", "scale_dp")
        cfg["model"].setdefault("dropout", 0.0)
        cfg["model"].setdefault("pos_embed", "learned")
    if cfg.get("format") != FORMAT:
        raise ValueError(f"{path}: format {cfg.get('format')!r}, not a {FORMAT} checkpoint")
    if cfg.get("version") != VERSION:
        raise ValueError(f"{path}: version {cfg.get('version')!r}: this module reads {VERSION}")
    return cfg


def read_train_state(ckpt: str) -> Tuple[Dict[str, torch.Tensor], Dict[str, Dict[str, torch.Tensor]]]:
    """The raw weights and the AdamW moments (``{name: {"exp_avg", "exp_avg_sq"}}``)."""
    from safetensors.torch import load_file

    ts = load_file(os.path.join(ckpt, TRAIN_STATE_FILE))
    params = {k[len("params."):]: v for k, v in ts.items() if k.startswith("params.")}
    moments: Dict[str, Dict[str, torch.Tensor]] = {}
    for k, v in ts.items():
        if k.startswith("optim."):
            name, _, kind = k[len("optim."):].rpartition(".")
            moments.setdefault(name, {})[kind] = v
    return params, moments
