"""Validation on held-out episodes with the EMA weights (``policy/src/trainer/validate.rs``):
the denoising loss at random timesteps with centre crops, and the error of full DDIM samples
against the recorded chunks, normalized and per dimension in raw units. The random numbers come
from a generator seeded by the run's seed alone, so every validation of a run draws the same
ones (as the Rust trainer's, though not the same numbers: those come from ChaCha8)."""

from __future__ import annotations

from typing import Any, Dict

import numpy as np
import torch

from .diffusion import NoiseScheduler, ddim_sample
from .model import ImagePolicy

__all__ = ["validate"]


@torch.no_grad()
def validate(model: ImagePolicy, cfg: Dict[str, Any], val: Any, batches: int, seed: int,
             step: int, device: torch.device) -> Dict[str, Any]:
    """Validates ``model`` on up to ``batches`` batches of the loader ``val`` (always the same
    ones: epoch 0); returns the ``"kind": "val"`` record of ``metrics.jsonl``."""
    m = cfg["model"]
    a = m["action_dim"]
    g = torch.Generator().manual_seed(int(seed) ^ 0x7A1)
    train = NoiseScheduler(cfg["diffusion"]["train_steps"])
    ddim = NoiseScheduler(cfg["diffusion"]["train_steps"])
    ddim.set_timesteps(cfg["diffusion"]["inference_steps"])
    act = cfg["normalizer"]["action"]
    scale = np.asarray(act["scale"], dtype=np.float64)
    offset = np.asarray(act["offset"], dtype=np.float64)
    val.set_epoch(0)
    loss_sum, valid_total, samples = 0.0, 0, 0
    se = ae = 0.0
    ae_raw = np.zeros(a)
    it = iter(val)
    for _ in range(max(batches, 1)):
        batch = next(it, None)
        if batch is None:
            break
        images = torch.from_numpy(batch["observation.images"]).to(device)
        state = torch.from_numpy(batch["observation.state"]).to(device)
        action = torch.from_numpy(batch["action"]).to(device)
        pad = batch["action_is_pad"]
        b = action.shape[0]
        cond = model.encode(images, state, None)
        t = torch.randint(0, train.train_steps, (b,), generator=g)
        noise = torch.randn(action.shape, generator=g).to(device)
        noisy = train.add_noise(action, noise, t.to(device))
        err = ((model(noisy, t.to(device), cond) - noise) ** 2).sum(-1).cpu().numpy()
        pred = ddim_sample(model, ddim, cond, torch.randn(action.shape, generator=g)).cpu().numpy()
        rec = batch["action"]
        keep = ~pad
        loss_sum += float(err[keep].astype(np.float64).sum())
        valid_total += int(keep.sum())
        e = (pred - rec).astype(np.float64)[keep]
        se += float((e * e).sum())
        ae += float(np.abs(e).sum())
        raw = lambda x: (x.astype(np.float64) - offset) / scale  # noqa: E731
        ae_raw += np.abs(raw(pred[keep]) - raw(rec[keep])).sum(0)
        samples += b
    n = max(valid_total, 1)
    return {"step": step, "samples": samples, "loss": loss_sum / (n * a), "action_mse": se / (n * a),
            "action_mae": ae / (n * a), "action_mae_raw": (ae_raw / n).tolist(),
            "action_names": list(cfg["action_names"])}
