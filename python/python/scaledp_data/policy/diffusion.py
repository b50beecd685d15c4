"""The noise schedule, a training step's random draws and the denoising loss, as the Rust
trainer defines them (``policy/src/scheduler.rs``, ``policy/src/trainer/loss.rs``).

- :class:`NoiseScheduler`: DDPM ``squaredcos_cap_v2`` over 100 steps, epsilon-prediction;
  DDIM with eta 0, "leading" spacing (90, 80, ..., 0), ``set_alpha_to_one``, x0 clipped to
  [-1, 1]. The numbers are diffusers' (betas in float64 stored as float32, the cumulative
  product of ``1 - beta`` accumulated in float64), so both trainers noise identically.
- :class:`Draws`: everything random in a training step -- one crop window per image, ``K``
  timesteps and noise tensors per sample. A step's draws are made for the global batch from one
  generator, so a sample gets the same draws whichever rank trains it; the parity tests hand
  the Rust trainer's draws in instead.
- :class:`DenoisingLoss`: the module DDP wraps; its forward is the summed squared error of a
  batch under given draws (the caller divides by the global count).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import torch
import torch.nn as nn

from .model import ImagePolicy, crop_size

__all__ = ["NoiseScheduler", "Draws", "DenoisingLoss", "ddim_sample", "loss_terms"]


def _alpha_bar(t: float) -> float:
    c = math.cos((t + 0.008) / 1.008 * (math.pi / 2))
    return c * c


class NoiseScheduler:
    """DDPM noising for training and DDIM steps for sampling over one cosine schedule."""

    def __init__(self, train_steps: int = 100):
        if train_steps < 1:
            raise ValueError("the diffusion needs at least 1 training step")
        n = float(train_steps)
        betas = [min(1 - _alpha_bar((i + 1) / n) / _alpha_bar(i / n), 0.999) for i in range(train_steps)]
        self.betas = torch.tensor(betas, dtype=torch.float64).to(torch.float32)
        alphas = (1.0 - self.betas).to(torch.float64)  # 1 - beta in float32, then widened
        self.alphas_cumprod = torch.cumprod(alphas, 0).to(torch.float32)
        self.timesteps = list(range(train_steps - 1, -1, -1))

    @property
    def train_steps(self) -> int:
        """T."""
        return len(self.betas)

    def set_timesteps(self, n: int) -> None:
        """``n`` sampling steps with leading spacing: t = i * (T // n), i = n-1 ... 0."""
        if not 1 <= n <= self.train_steps:
            raise ValueError(f"{n} sampling steps: must be 1 ..= {self.train_steps}")
        ratio = self.train_steps // n
        self.timesteps = [i * ratio for i in range(n - 1, -1, -1)]

    def add_noise(self, x0: torch.Tensor, noise: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """``sqrt(a_t) x0 + sqrt(1 - a_t) noise``, one timestep per row of the first axis."""
        a = self.alphas_cumprod.to(x0.device)[t]
        shape = (-1,) + (1,) * (x0.dim() - 1)
        return x0 * a.sqrt().reshape(shape) + noise * (1.0 - a).sqrt().reshape(shape)

    def step(self, eps: torch.Tensor, t: int, sample: torch.Tensor) -> torch.Tensor:
        """One DDIM step (eta 0) from ``sample`` at timestep ``t`` given the predicted noise."""
        n = max(len(self.timesteps), 1)
        a_t = float(self.alphas_cumprod[t])
        prev = t - self.train_steps // n
        a_prev = float(self.alphas_cumprod[prev]) if prev >= 0 else 1.0
        f32 = lambda v: torch.tensor(v, dtype=torch.float32, device=sample.device)  # noqa: E731
        s1, s0 = f32(math.sqrt(1.0 - a_t)), f32(math.sqrt(a_t))
        p1, p0 = f32(math.sqrt(1.0 - a_prev)), f32(math.sqrt(a_prev))
        x0 = ((sample - eps * s1) / s0).clamp(-1.0, 1.0)
        return x0 * p0 + eps * p1


@torch.no_grad()
def ddim_sample(policy: ImagePolicy, scheduler: NoiseScheduler, cond: torch.Tensor,
                noise: Optional[torch.Tensor] = None,
                generator: Optional[torch.Generator] = None) -> torch.Tensor:
    """Normalized action chunks ``[B, C, A]`` for conditions ``cond`` ``[B, cond_dim]``: from
    ``noise`` (or Gaussian noise of ``generator``), one DDIM step per timestep of
    ``scheduler``."""
    cfg = policy.cfg
    b = cond.shape[0]
    if noise is None:
        noise = torch.randn((b, cfg["action_chunk"], cfg["action_dim"]), generator=generator)
    x = noise.to(cond.device, torch.float32)
    for t in scheduler.timesteps:
        c = policy.condition(torch.full((b,), float(t), device=cond.device), cond)
        x = scheduler.step(policy.denoise(x, c), t, x)
    return x


@dataclass
class Draws:
    """A training step's random numbers for ``B`` samples: ``crops`` int64
    ``[cams, B, To, 2]`` (top, left of each image's window), ``timesteps`` int64 ``[B, K]``,
    ``noise`` float32 ``[B, K, C, A]``."""

    crops: torch.Tensor
    timesteps: torch.Tensor
    noise: torch.Tensor

    @classmethod
    def random(cls, cfg: dict, batch: int, noise_samples: int, train_steps: int,
               generator: torch.Generator) -> Draws:
        """Uniform windows (every valid top-left), uniform timesteps, standard normal noise."""
        cams, to = len(cfg["cameras"]), cfg["obs_horizon"]
        cw, ch = crop_size(cfg)
        g = generator
        top = torch.randint(0, cfg["image_height"] - ch + 1, (cams, batch, to, 1), generator=g)
        left = torch.randint(0, cfg["image_width"] - cw + 1, (cams, batch, to, 1), generator=g)
        k = max(1, noise_samples)
        t = torch.randint(0, train_steps, (batch, k), generator=g)
        noise = torch.randn((batch, k, cfg["action_chunk"], cfg["action_dim"]), generator=g)
        return cls(torch.cat([top, left], dim=-1), t, noise)

    def select(self, rows: torch.Tensor) -> Draws:
        """The draws of samples ``rows`` (e.g. a rank's share of the global batch)."""
        return Draws(self.crops[:, rows], self.timesteps[rows], self.noise[rows])

    def to(self, device: torch.device) -> Draws:
        """On ``device``."""
        return Draws(self.crops.to(device), self.timesteps.to(device), self.noise.to(device))


def loss_terms(action_is_pad: torch.Tensor, action_dim: int, noise_samples: int,
               mask_padding: bool) -> int:
    """How many squared errors the loss averages: (action steps counted) x A x K, the steps
    counted being every step, or the unpadded ones with ``mask_padding``."""
    steps = int((~action_is_pad).sum()) if mask_padding else action_is_pad.numel()
    return max(steps, 1) * action_dim * max(1, noise_samples)


class DenoisingLoss(nn.Module):
    """The training objective around a :class:`ImagePolicy` (what DDP wraps): the observation
    encoded once per sample, ``K`` (timestep, noise) draws per encoding, the summed squared
    error of the predicted noise over every action step (or the unpadded ones)."""

    def __init__(self, policy: ImagePolicy, scheduler: NoiseScheduler, mask_padding: bool = False):
        super().__init__()
        self.policy = policy
        self.mask_padding = mask_padding
        self.register_buffer("alphas_cumprod", scheduler.alphas_cumprod.clone(), persistent=False)

    def forward(self, images: torch.Tensor, state: torch.Tensor, action: torch.Tensor,
                action_is_pad: torch.Tensor, crops: torch.Tensor, timesteps: torch.Tensor,
                noise: torch.Tensor) -> torch.Tensor:
        """Sum over samples, draws, action steps and dimensions of (eps_hat - eps)^2."""
        b, k = timesteps.shape
        cond = self.policy.encode(images, state, crops)
        cond = cond.repeat_interleave(k, dim=0)
        x0 = action.to(torch.float32).repeat_interleave(k, dim=0)
        t = timesteps.reshape(-1)
        eps = noise.reshape(b * k, *noise.shape[2:])
        a = self.alphas_cumprod[t][:, None, None]
        noisy = x0 * a.sqrt() + eps * (1.0 - a).sqrt()
        se = (self.policy(noisy, t, cond) - eps) ** 2
        if self.mask_padding:
            keep = (~action_is_pad).repeat_interleave(k, dim=0)[:, :, None]
            se = se * keep.to(se.dtype)
        return se.sum()
