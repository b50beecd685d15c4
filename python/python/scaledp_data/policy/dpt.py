"""DP-T, the ScaleDP paper's baseline, in PyTorch: diffusion_policy's ``TransformerForDiffusion``
as its hybrid image policy builds it (``time_as_cond``, ``obs_as_cond``, ``n_cond_layers: 0``),
on this package's encoders. The Rust policy (``policy/src/model/dpt.rs`` and its CPU engine) is
held to it.

- The memory: the diffusion step as diffusion_policy's ``SinusoidalPosEmb`` (sin first, then
  cos; no MLP), one token per observation step through ``cond_obs_emb``, plus ``cond_pos_emb``,
  through the ``encoder`` MLP (Linear, Mish, Linear).
- The action tokens: ``input_emb`` + ``pos_emb``, then torch's own ``nn.TransformerDecoder`` of
  pre-LN ``nn.TransformerDecoderLayer``\\ s (exact GELU, dropout ``p_drop_attn``), ``ln_f``,
  ``head``; with ``attention: causal`` (DP-T's default) the causal mask and the memory mask
  (action t sees condition token s when t >= s - 1).

State-dict names are diffusion_policy's (``model.`` is its ``TransformerForDiffusion``):
``model.decoder.layers.N.self_attn.in_proj_weight`` and so on; the encoders keep this package's
``obs_encoder.<camera>.*``. The masks are buffers that are not saved (they follow from the
configuration).
"""

from __future__ import annotations

import math
from typing import Any, Dict, Optional

import numpy as np
import torch
import torch.nn as nn

from .model import ImagePolicy

__all__ = ["DPTPolicy", "TransformerForDiffusion", "sinusoidal_pos_emb"]


def sinusoidal_pos_emb(t: torch.Tensor, dim: int) -> torch.Tensor:
    """diffusion_policy's ``SinusoidalPosEmb(dim)``: ``[sin(t f), cos(t f)]`` with
    ``f_i = exp(-i ln(1e4) / (dim/2 - 1))``, in float32 operations as the Rust code computes
    them."""
    half = dim // 2
    e = np.float32(math.log(10000.0) / (max(half, 2) - 1))
    i = torch.arange(half, dtype=torch.float32)
    freqs = torch.exp(i * torch.tensor(-e, dtype=torch.float32)).to(t.device)
    args = t.to(torch.float32)[:, None] * freqs[None]
    out = torch.cat([torch.sin(args), torch.cos(args)], dim=-1)
    if dim > 2 * half:
        out = torch.cat([out, out.new_zeros(out.shape[0], dim - 2 * half)], dim=-1)
    return out


def masks(horizon: int, obs_steps: int) -> tuple:
    """DP-T's additive masks: causal ``[T, T]`` and memory ``[T, 1 + To]`` (0 or -inf)."""
    t = torch.arange(horizon)[:, None]
    causal = torch.zeros(horizon, horizon).masked_fill(torch.arange(horizon)[None] > t, float("-inf"))
    s = torch.arange(obs_steps + 1)[None]
    memory = torch.zeros(horizon, obs_steps + 1).masked_fill(~(t >= s - 1), float("-inf"))
    return causal, memory


class TransformerForDiffusion(nn.Module):
    """diffusion_policy's denoiser at ``time_as_cond=True``, ``obs_as_cond=True``,
    ``n_cond_layers=0``: noisy actions ``[B, T, A]``, timesteps ``[B]``, observation features
    ``[B, To, F]`` -> predicted noise."""

    def __init__(self, input_dim: int, output_dim: int, horizon: int, n_obs_steps: int,
                 cond_dim: int, n_layer: int = 8, n_head: int = 4, n_emb: int = 256,
                 p_drop_emb: float = 0.0, p_drop_attn: float = 0.3, causal_attn: bool = True):
        super().__init__()
        t_cond = 1 + n_obs_steps
        self.n_emb = n_emb
        self.input_emb = nn.Linear(input_dim, n_emb)
        self.pos_emb = nn.Parameter(torch.zeros(1, horizon, n_emb))
        self.drop = nn.Dropout(p_drop_emb)
        self.cond_obs_emb = nn.Linear(cond_dim, n_emb)
        self.cond_pos_emb = nn.Parameter(torch.zeros(1, t_cond, n_emb))
        self.encoder = nn.Sequential(nn.Linear(n_emb, 4 * n_emb), nn.Mish(), nn.Linear(4 * n_emb, n_emb))
        layer = nn.TransformerDecoderLayer(d_model=n_emb, nhead=n_head, dim_feedforward=4 * n_emb,
                                           dropout=p_drop_attn, activation="gelu",
                                           batch_first=True, norm_first=True)
        self.decoder = nn.TransformerDecoder(decoder_layer=layer, num_layers=n_layer)
        if causal_attn:
            mask, memory_mask = masks(horizon, n_obs_steps)
            self.register_buffer("mask", mask, persistent=False)
            self.register_buffer("memory_mask", memory_mask, persistent=False)
        else:
            self.mask = None
            self.memory_mask = None
        self.ln_f = nn.LayerNorm(n_emb)
        self.head = nn.Linear(n_emb, output_dim)

    def initialize(self, generator: Optional[torch.Generator] = None) -> None:
        """diffusion_policy's ``_init_weights``: Linear weights and the attention in-projections
        N(0, 0.02), biases 0, LayerNorms 1 / 0, both positional embeddings N(0, 0.02)."""
        g = generator
        with torch.no_grad():
            for m in self.modules():
                if isinstance(m, nn.Linear):
                    m.weight.copy_(torch.randn(m.weight.shape, generator=g) * 0.02)
                    m.bias.zero_()
                elif isinstance(m, nn.MultiheadAttention):
                    m.in_proj_weight.copy_(torch.randn(m.in_proj_weight.shape, generator=g) * 0.02)
                    m.in_proj_bias.zero_()
                elif isinstance(m, nn.LayerNorm):
                    m.weight.fill_(1.0)
                    m.bias.zero_()
            for p in (self.pos_emb, self.cond_pos_emb):
                p.copy_(torch.randn(p.shape, generator=g) * 0.02)

    def memory(self, t: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        """The condition tokens through the condition MLP, ``[B, 1 + To, n_emb]``."""
        time_emb = sinusoidal_pos_emb(t, self.n_emb).unsqueeze(1)
        x = torch.cat([time_emb, self.cond_obs_emb(cond)], dim=1)
        return self.encoder(self.drop(x + self.cond_pos_emb[:, :x.shape[1]]))

    def decode(self, sample: torch.Tensor, memory: torch.Tensor) -> torch.Tensor:
        """The predicted noise of ``sample`` under ``memory``."""
        x = self.drop(self.input_emb(sample) + self.pos_emb[:, :sample.shape[1]])
        x = self.decoder(tgt=x, memory=memory, tgt_mask=self.mask, memory_mask=self.memory_mask)
        return self.head(self.ln_f(x))

    def forward(self, sample: torch.Tensor, timestep: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        return self.decode(sample, self.memory(timestep, cond))


class DPTPolicy(ImagePolicy):
    """The encoders and DP-T under ``model.``: the same condition as ScaleDP (per observation
    step the camera features, then the state), one memory token per observation step."""

    def __init__(self, cfg: Dict[str, Any]):
        super().__init__(cfg)
        self.model = TransformerForDiffusion(
            input_dim=cfg["action_dim"], output_dim=cfg["action_dim"],
            horizon=cfg["action_chunk"], n_obs_steps=cfg["obs_horizon"],
            cond_dim=self.cond_dim // cfg["obs_horizon"], n_layer=cfg["depth"],
            n_head=cfg["heads"], n_emb=cfg["hidden"], p_drop_emb=0.0,
            p_drop_attn=float(cfg.get("dropout", 0.0)),
            causal_attn=cfg.get("attention", "causal") == "causal")
        self.initialize()

    def initialize(self, generator: Optional[torch.Generator] = None) -> None:
        """The encoders as torchvision, then DP-T as diffusion_policy initialises it."""
        self.initialize_encoders(generator)
        self.model.initialize(generator)

    def condition(self, t: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        """The memory ``[B, 1 + To, d]`` of timesteps ``t`` and conditions ``[B, cond_dim]``."""
        b, to = cond.shape[0], self.cfg["obs_horizon"]
        return self.model.memory(t, cond.reshape(b, to, -1))

    def denoise(self, x: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
        """The predicted noise of ``x`` ``[B, C, A]`` under the memory ``c``."""
        return self.model.decode(x, c)
