"""Training options: the flags of ``scaledp train`` with the same names, meanings and defaults,
and the options object a checkpoint stores under ``config.json``'s ``train`` -- the Rust
``TrainOptions`` serialized field by field, so either trainer resumes the other's runs.
"""

from __future__ import annotations

import argparse
import math
from typing import Any, Dict, Optional, Tuple

__all__ = ["MODEL_SIZES", "DPT_DIMS", "DPT_DROPOUT", "PRESETS", "add_arguments", "default_options", "options_from_args", "cosine_lr",
           "ema_decay"]

#: The paper's sizes: depth, width, heads.
MODEL_SIZES = {"ti": (8, 256, 4), "s": (12, 384, 6), "b": (12, 768, 12), "l": (24, 1024, 16),
               "h": (32, 1280, 16)}

#: DP-T's defaults (diffusion_policy's hybrid image policy): layers, width, heads; and its
#: ``p_drop_attn``.
DPT_DIMS = (8, 256, 4)
DPT_DROPOUT = 0.3


#: ``TrainOptions::preset`` (policy/src/trainer/presets.rs): what each named recipe changes.
PRESETS: Dict[str, Dict[str, Any]] = {
    "paper": {"attention": "non_causal"},
    "cpu-sim": {"resnet_width": 32, "noise_samples": 2, "batch_size": 64, "lr": 3e-4,
                "warmup_steps": 500, "steps": 3000, "checkpoint_every": 500, "val_ratio": 0.0,
                "val_every": 0},
    "cpu-metaworld": {"resnet_width": 32, "noise_samples": 2, "batch_size": 64, "lr": 3e-4,
                      "warmup_steps": 500, "steps": 2500, "checkpoint_every": 500,
                      "val_ratio": 0.0, "val_every": 0, "image_size": [84, 84]},
    "cpu-aloha": {"resnet_width": 32, "noise_samples": 2, "batch_size": 64, "lr": 3e-4,
                  "warmup_steps": 500, "steps": 2500, "checkpoint_every": 500,
                  "val_ratio": 0.0, "val_every": 0, "image_size": [128, 96], "action_chunk": 32},
}


def default_options() -> Dict[str, Any]:
    """``TrainOptions::default()``: every default is the paper's / diffusion_policy's, except
    ScaleDP's attention: causal (``default_attention`` in policy/src/trainer/options.rs says why;
    the paper's non-causal is the ``paper`` preset)."""
    return {
        "size": "ti", "denoiser": None, "resnet_width": 64, "steps": 10_000, "batch_size": 64,
        "micro_batch": None, "lr": 1e-4, "warmup_steps": 500,
        "adamw": {"beta1": 0.9, "beta2": 0.95, "eps": 1e-8, "weight_decay": 1e-3,
                  "encoder_weight_decay": 1e-6},
        "ema": {"inv_gamma": 1.0, "power": 0.75, "min_value": 0.0, "max_value": 0.9999,
                "update_after_step": 0},
        "grad_clip": None, "seed": 0, "checkpoint_every": 1000, "val_every": 1000,
        "val_ratio": 0.05, "val_batches": 4, "obs_horizon": 2, "action_chunk": 16,
        "cameras": None, "image_size": None, "crop": 0.9, "loader_threads": 0,
        "max_episodes": None, "loss": {"noise_samples": 1, "mask_padding": False},
        "state_norm": "min_max", "image_range": "symmetric", "attention": "causal",
        "arch": "scale_dp", "dropout": None, "pos_embed": "learned",
    }


def _size(s: str) -> Tuple[int, int]:
    try:
        w, h = s.split("x")
        return int(w), int(h)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--image-size {s}: WxH, e.g. 84x84") from None


def _triple(s: str) -> Tuple[int, int, int]:
    try:
        d, w, h = (int(v) for v in s.split(","))
        return d, w, h
    except ValueError:
        raise argparse.ArgumentTypeError(f"--denoiser {s}: DEPTH,WIDTH,HEADS, e.g. 2,64,4") from None


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of ``scaledp train`` (tools/src/commands/train.rs), same names and defaults."""
    p.add_argument("dataset", nargs="?", help="the dataset: a directory or s3://bucket/prefix "
                   "(not needed with --resume)")
    p.add_argument("--preset", choices=sorted(PRESETS), help="a named recipe to start from "
                   "(cpu-sim: ScaleDP-Ti on the simulated cube task within three hours on two "
                   "CPU cores; paper: the paper's ScaleDP, non-causal); the other flags override "
                   "it one by one")
    p.add_argument("--model", default="ti", help="model: a ScaleDP size (ti, s, b, l or h) or "
                   "dp-t (the paper's baseline, diffusion_policy's transformer)")
    p.add_argument("--layers", type=int, help="denoiser depth instead of the model's [ScaleDP: "
                   "the size's; DP-T 8]")
    p.add_argument("--width", type=int, help="denoiser width instead of the model's [DP-T 256]")
    p.add_argument("--heads", type=int, help="attention heads instead of the model's [DP-T 4]")
    p.add_argument("--dropout", type=float, help="dropout while training [DP-T 0.3; ScaleDP "
                   "none]")
    p.add_argument("--out", metavar="DIR", help="run directory (metrics.jsonl, checkpoints/step_*)")
    p.add_argument("--resume", metavar="DIR", help="continue the run in this directory from its "
                   "latest checkpoint")
    p.add_argument("--steps", type=int, help="optimizer steps in total (default 10000)")
    p.add_argument("--batch-size", type=int,
                   help="samples per step: the global batch, split evenly over the ranks [64]")
    p.add_argument("--micro-batch", type=int, help="forward/backward at most this many samples "
                   "at a time per rank (same update, less memory)")
    p.add_argument("--lr", type=float, help="peak learning rate [1e-4]")
    p.add_argument("--warmup-steps", type=int, help="warm-up steps [500]")
    p.add_argument("--seed", type=int, default=0, help="seed of the weights, data order, crops "
                   "and noise")
    p.add_argument("--device", default="auto", help="cpu, cuda or auto (default: cuda when "
                   "available: NCCL across the ranks, else the CPU and gloo)")
    p.add_argument("--checkpoint-every", type=int, help="checkpoint every N steps "
                   "(and at the end) [1000]")
    p.add_argument("--val-every", type=int, help="validate every N steps (0: never) [1000]")
    p.add_argument("--val-ratio", type=float, help="fraction of episodes held out "
                   "for validation [0.05]")
    p.add_argument("--grad-clip", type=float, help="clip the global gradient norm")
    p.add_argument("--crop", type=float, default=0.9, help="crop side / image side (random in "
                   "training, centred in inference)")
    p.add_argument("--obs-horizon", type=int, default=None,
                   help="observation frames per sample, To [2, or the preset's]")
    p.add_argument("--action-chunk", type=int, default=None,
                   help="actions per chunk, C [16, or the preset's]")
    p.add_argument("--image-size", type=_size, metavar="WxH", help="resize images to WxH before "
                   "the crop (e.g. 84x84)")
    p.add_argument("--cameras", type=lambda s: [c for c in s.split(",") if c], default=[],
                   help="cameras to use, comma-separated short names (default: all)")
    p.add_argument("--resnet-width", type=int, help="channels of the ResNet-18 trunks' "
                   "first stage (64: the paper's encoder) [64]")
    p.add_argument("--noise-samples", type=int, help="(timestep, noise) draws per "
                   "encoded observation [1]")
    p.add_argument("--attention", help="non-causal (the paper's ScaleDP) or causal [causal; "
                   "DP-T: its own masks]")
    p.add_argument("--pos-embed", help="ScaleDP's positional embedding: learned (the paper's) "
                   "or sin-cos (DiT's fixed table, not trained) [learned]")
    p.add_argument("--mask-padding", action="store_true", help="leave action steps past an "
                   "episode's end out of the loss")
    p.add_argument("--state-norm", default="min-max", help="min-max or mean-std")
    p.add_argument("--weight-decay", type=float, default=1e-3, help="weight decay of the "
                   "denoiser's Linear weights")
    p.add_argument("--encoder-weight-decay", type=float, default=1e-6, help="weight decay of "
                   "every encoder parameter")
    p.add_argument("--dry-run", action="store_true", help="print the parameter counts and stop")
    # Beyond `scaledp train`'s flags: what the Rust TrainOptions offer its tests, and a record
    # of the samples each rank trained on.
    p.add_argument("--denoiser", type=_triple, metavar="DEPTH,WIDTH,HEADS",
                   help="a denoiser of this shape instead of --model's preset (tests, ablations)")
    p.add_argument("--log-samples", action="store_true", help="write samples-rank<R>.jsonl in the "
                   "run directory: the (episode_index, frame_index) pairs each step trained on")
    p.add_argument("--view", nargs="?", const="", default=None, metavar="URL",
                   help="plot the loss, lr and validation errors in a rerun viewer (needs "
                   "rerun-sdk): a new one, or the one at URL")


def _attention(s: str) -> str:
    v = s.lower().replace("-", "_")
    if v in ("non_causal", "noncausal", "full"):
        return "non_causal"
    if v == "causal":
        return "causal"
    raise ValueError(f"attention {s!r}: non-causal or causal")


def _pos_embed(s: str) -> str:
    v = s.lower().replace("-", "").replace("_", "")
    if v in ("learned", "sincos"):
        return "learned" if v == "learned" else "sin_cos"
    raise ValueError(f"pos_embed {s!r}: learned or sin-cos")


def options_from_args(a: argparse.Namespace) -> Dict[str, Any]:
    """The options of a new run from the command line (``options()`` of train.rs)."""
    model = a.model.lower().replace("_", "-")
    dpt = model in ("dp-t", "dpt")
    if not dpt and model not in MODEL_SIZES:
        raise ValueError(f"model {a.model!r}: one of ti, s, b, l, h, dp-t")
    state_norm = {"min-max": "min_max", "min_max": "min_max", "mean-std": "mean_std",
                  "mean_std": "mean_std"}.get(a.state_norm)
    if state_norm is None:
        raise ValueError(f"--state-norm {a.state_norm}: min-max or mean-std")
    o = default_options()
    preset = getattr(a, "preset", None)
    if preset is not None:
        if preset not in PRESETS:
            raise ValueError(f"--preset {preset}: one of {', '.join(sorted(PRESETS))}")
        o.update({k: v for k, v in PRESETS[preset].items() if k != "noise_samples"})
        o["loss"] = dict(o["loss"], noise_samples=PRESETS[preset].get("noise_samples", 1))
    # Naming another architecture than the preset's sets its default attention (causal for
    # both); the same architecture keeps the preset's (``paper``: non-causal).
    arch = "dp_t" if dpt else "scale_dp"
    attention = a.attention if a.attention is not None else (
        "causal" if arch != o["arch"] else o["attention"])
    o.update({"size": "ti" if dpt else model, "seed": a.seed, "crop": a.crop,
              "attention": _attention(attention), "state_norm": state_norm,
              "arch": arch})
    if getattr(a, "pos_embed", None) is not None:
        o["pos_embed"] = _pos_embed(a.pos_embed)
    for key in ("obs_horizon", "action_chunk"):
        if getattr(a, key, None) is not None:
            o[key] = getattr(a, key)
    if getattr(a, "dropout", None) is not None:
        o["dropout"] = float(a.dropout)
    for key in ("batch_size", "lr", "warmup_steps", "checkpoint_every", "val_every",
                "val_ratio", "resnet_width"):
        if getattr(a, key, None) is not None:
            o[key] = getattr(a, key)
    k = a.noise_samples if getattr(a, "noise_samples", None) is not None else o["loss"]["noise_samples"]
    o["loss"] = {"noise_samples": max(1, k), "mask_padding": bool(a.mask_padding)}
    o["adamw"] = dict(o["adamw"], weight_decay=a.weight_decay,
                      encoder_weight_decay=a.encoder_weight_decay)
    if a.steps is not None:
        o["steps"] = a.steps
    if a.micro_batch is not None:
        o["micro_batch"] = a.micro_batch
    if a.grad_clip is not None:
        o["grad_clip"] = a.grad_clip
    if a.image_size is not None:
        o["image_size"] = list(a.image_size)
    if a.cameras:
        o["cameras"] = list(a.cameras)
    if getattr(a, "denoiser", None):
        o["denoiser"] = list(a.denoiser)
    shape = [getattr(a, k, None) for k in ("layers", "width", "heads")]
    if any(v is not None for v in shape):
        base = o["denoiser"] or list(DPT_DIMS if dpt else MODEL_SIZES[o["size"]])
        o["denoiser"] = [v if v is not None else b for v, b in zip(shape, base)]
    if o["steps"] < 1 or o["batch_size"] < 1:
        raise ValueError("steps and batch size must be at least 1")
    return o


def encoder_decay(o: Dict[str, Any]) -> Optional[float]:
    """The encoders' weight decay, or None for runs saved before the encoders had their own
    group (they decayed Linear/Conv weights at ``weight_decay``)."""
    v = o["adamw"].get("encoder_weight_decay")
    return None if v is None or (isinstance(v, float) and math.isnan(v)) else float(v)


def cosine_lr(base: float, step: int, warmup: int, total: int) -> float:
    """diffusers' ``get_cosine_schedule_with_warmup``: the learning rate of the update made after
    ``step`` earlier updates."""
    if step < warmup:
        return base * step / max(warmup, 1)
    progress = (step - warmup) / max(total - warmup, 1)
    return base * max(0.0, 0.5 * (1.0 + math.cos(math.pi * progress)))


def ema_decay(ema: Dict[str, Any], step: int) -> float:
    """diffusion_policy's ``EMAModel`` decay of the update made after ``step`` earlier updates
    (0 for the first two: they copy the weights)."""
    k = max(0, step - (ema["update_after_step"] + 1))
    if k == 0:
        return 0.0
    value = 1.0 - (1.0 + k / ema["inv_gamma"]) ** (-ema["power"])
    return max(min(value, ema["max_value"]), ema["min_value"])
