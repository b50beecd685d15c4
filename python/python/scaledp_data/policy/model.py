"""The ScaleDP network in PyTorch, the one definition the Rust policy (``policy/`` crate) is
held to: its state dict has exactly the names of a checkpoint's ``model.safetensors``, so a
checkpoint of either trainer loads here with ``load_state_dict(strict=True)``.

- One encoder per camera (diffusion_policy / robomimic ``VisualCore``): crop, pixels to the
  model's range, ResNet-18 trunk (torchvision names, BatchNorm replaced by GroupNorm(C/16)),
  SpatialSoftmax (1x1 conv to keypoints, softmax, expected (x, y) -> 2 values per keypoint),
  Linear. Per observation step the camera features, then the normalized state; the condition is
  that flattened over To.
- The DiT denoiser over the C action tokens: ``x_embedder`` + ``pos_embed``; ``c = t_emb +
  cond_emb``; adaLN-Zero blocks (LayerNorm without affine, eps 1e-6; fused ``qkv`` attention,
  non-causal unless ``attention: causal``; tanh-GELU MLP); ``final_layer``.

The arithmetic that decides bits follows the Rust code: the crop size rounds half away from
zero, pixels go through the same float32 lookup table, the SpatialSoftmax grid and the timestep
frequencies are computed as Rust computes them.
"""

from __future__ import annotations

import json
import math
import os
from typing import Any, Dict, Optional, Tuple

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

__all__ = ["ImagePolicy", "ScaleDPPolicy", "build_policy", "policy_class", "crop_size",
           "camera_short_name", "timestep_embedding"]

#: Width of the sinusoidal timestep embedding.
FREQ_DIM = 256


def crop_size(cfg: Dict[str, Any]) -> Tuple[int, int]:
    """(width, height) after the crop: ``round(side * crop)`` (half away from zero, as Rust's
    ``f64::round``), clamped to [1, side]."""
    def side(s: int) -> int:
        return min(max(int(math.floor(s * float(cfg["crop"]) + 0.5)), 1), s)

    return side(int(cfg["image_width"])), side(int(cfg["image_height"]))


def camera_short_name(key: str) -> str:
    """The weight-name part of a camera key: without ``observation.images.``, dots as
    underscores (``obs_encoder.<short>.*``)."""
    s = key[len("observation.images."):] if key.startswith("observation.images.") else key
    return s.replace(".", "_")


def pixel_table(image_range: str) -> torch.Tensor:
    """float32 value of each uint8 pixel: ``p * scale + offset`` with the scale rounded to
    float32 first and the sum taken in float64, exactly as the Rust crop does."""
    if image_range == "symmetric":
        scale, offset = np.float32(2.0 / 255.0), -1.0
    elif image_range == "unit":
        scale, offset = np.float32(1.0 / 255.0), 0.0
    else:
        raise ValueError(f"image_range {image_range!r}: symmetric or unit")
    p = np.arange(256, dtype=np.float64)
    return torch.from_numpy((p * np.float64(scale) + offset).astype(np.float32))


def _centre(margin: int) -> int:
    """torchvision's ``center_crop`` offset ``int(round(margin / 2))`` (half to even)."""
    return int(round(margin / 2.0))


def gn(c: int) -> nn.GroupNorm:
    """diffusion_policy's replacement of a BatchNorm over ``c`` channels."""
    return nn.GroupNorm(max(1, c // 16), c)


class BasicBlock(nn.Module):
    """torchvision's ResNet basic block with GroupNorm."""

    def __init__(self, c_in: int, c_out: int, stride: int):
        super().__init__()
        self.conv1 = nn.Conv2d(c_in, c_out, 3, stride, 1, bias=False)
        self.bn1 = gn(c_out)
        self.conv2 = nn.Conv2d(c_out, c_out, 3, 1, 1, bias=False)
        self.bn2 = gn(c_out)
        self.downsample = None
        if stride != 1 or c_in != c_out:
            self.downsample = nn.Sequential(
                nn.Conv2d(c_in, c_out, 1, stride, bias=False), gn(c_out))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = F.relu(self.bn1(self.conv1(x)))
        y = self.bn2(self.conv2(y))
        skip = x if self.downsample is None else self.downsample(x)
        return F.relu(y + skip)


class ResNet18Trunk(nn.Module):
    """torchvision resnet18 ``children()[:-2]`` (no avgpool, no fc) with GroupNorm."""

    def __init__(self, width: int = 64):
        super().__init__()
        self.conv1 = nn.Conv2d(3, width, 7, 2, 3, bias=False)
        self.bn1 = gn(width)
        c = width
        for i, mult in enumerate([1, 2, 4, 8]):
            stride = 1 if i == 0 else 2
            w = width * mult
            layer = nn.Sequential(BasicBlock(c, w, stride), BasicBlock(w, w, 1))
            setattr(self, f"layer{i + 1}", layer)
            c = width * mult

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = F.max_pool2d(F.relu(self.bn1(self.conv1(x))), 3, 2, 1)
        for i in range(4):
            x = getattr(self, f"layer{i + 1}")(x)
        return x


def _linspace(n: int) -> np.ndarray:
    """linspace(-1, 1, n) computed in float64 and rounded, as the Rust grid (-1 for n = 1)."""
    if n <= 1:
        return np.full(max(n, 1), -1.0, dtype=np.float32)
    return (-1.0 + 2.0 * np.arange(n, dtype=np.float64) / (n - 1)).astype(np.float32)


class SpatialSoftmax(nn.Module):
    """robomimic's SpatialSoftmax: 1x1 conv to keypoints, softmax over the pixels, expected
    (x, y) -> ``[N, 2 * keypoints]`` (x0, y0, x1, y1, ...)."""

    def __init__(self, c_in: int, keypoints: int = 32):
        super().__init__()
        self.nets = nn.Conv2d(c_in, keypoints, 1)
        self.keypoints = keypoints

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.nets(x)
        n, k, h, w = x.shape
        gx = torch.from_numpy(np.tile(_linspace(w), h)).to(x.device, x.dtype)
        gy = torch.from_numpy(np.repeat(_linspace(h), w)).to(x.device, x.dtype)
        att = F.softmax(x.reshape(n * k, h * w), dim=-1)
        xy = torch.stack([att @ gx, att @ gy], dim=1)
        return xy.reshape(n, 2 * k)


class ObsEncoder(nn.Module):
    """One camera's encoder: ``[N, 3, h, w]`` in the model's pixel range -> ``[N, feature_dim]``."""

    def __init__(self, width: int = 64, keypoints: int = 32, feature_dim: int = 64):
        super().__init__()
        self.backbone = ResNet18Trunk(width)
        self.pool = SpatialSoftmax(8 * width, keypoints)
        self.linear = nn.Linear(2 * keypoints, feature_dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.linear(self.pool(self.backbone(x)))


def modulate(x: torch.Tensor, shift: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """``x * (1 + scale) + shift`` with ``[B, d]`` modulations over the tokens of ``[B, T, d]``."""
    return x * (1 + scale.unsqueeze(1)) + shift.unsqueeze(1)


def timestep_embedding(t: torch.Tensor, dim: int = FREQ_DIM) -> torch.Tensor:
    """DiT's ``[cos(t f), sin(t f)]`` with ``f_i = exp(-ln(1e4) i / (dim / 2))``, in float32
    operations as the Rust code computes them."""
    half = dim // 2
    ln = torch.tensor(10000.0, dtype=torch.float32).log()
    i = torch.arange(half, dtype=torch.float32)
    freqs = torch.exp(-ln * i / torch.tensor(float(half), dtype=torch.float32)).to(t.device)
    args = t.to(torch.float32)[:, None] * freqs[None]
    return torch.cat([torch.cos(args), torch.sin(args)], dim=-1)


class TimestepEmbedder(nn.Module):
    """The sinusoidal embedding, then Linear, SiLU, Linear (``t_embedder.mlp.{0,2}``)."""

    def __init__(self, d: int, freq: int = FREQ_DIM):
        super().__init__()
        self.mlp = nn.Sequential(nn.Linear(freq, d), nn.SiLU(), nn.Linear(d, d))
        self.freq = freq

    def forward(self, t: torch.Tensor) -> torch.Tensor:
        return self.mlp(timestep_embedding(t, self.freq))


class Attention(nn.Module):
    """Multi-head self-attention with a fused ``qkv``; no mask (ScaleDP) or causal (ablation)."""

    def __init__(self, d: int, heads: int, causal: bool = False):
        super().__init__()
        self.heads = heads
        self.causal = causal
        self.qkv = nn.Linear(d, 3 * d)
        self.proj = nn.Linear(d, d)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, n, d = x.shape
        qkv = self.qkv(x).reshape(b, n, 3, self.heads, d // self.heads).permute(2, 0, 3, 1, 4)
        y = F.scaled_dot_product_attention(qkv[0], qkv[1], qkv[2], is_causal=self.causal)
        return self.proj(y.transpose(1, 2).reshape(b, n, d))


class Mlp(nn.Module):
    """timm's ``Mlp``: fc1, tanh-GELU, fc2."""

    def __init__(self, d: int, hidden: int):
        super().__init__()
        self.fc1 = nn.Linear(d, hidden)
        self.fc2 = nn.Linear(hidden, d)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.fc2(F.gelu(self.fc1(x), approximate="tanh"))


def _ln(v: torch.Tensor) -> torch.Tensor:
    return F.layer_norm(v, v.shape[-1:], eps=1e-6)


class Block(nn.Module):
    """A DiT block with adaLN-Zero modulation (shift, scale, gate for attention and MLP)."""

    def __init__(self, d: int, heads: int, mlp_ratio: int = 4, causal: bool = False):
        super().__init__()
        self.attn = Attention(d, heads, causal)
        self.mlp = Mlp(d, mlp_ratio * d)
        self.adaLN_modulation = nn.Sequential(nn.SiLU(), nn.Linear(d, 6 * d))

    def forward(self, x: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
        m = self.adaLN_modulation(c).chunk(6, dim=1)
        x = x + m[2].unsqueeze(1) * self.attn(modulate(_ln(x), m[0], m[1]))
        return x + m[5].unsqueeze(1) * self.mlp(modulate(_ln(x), m[3], m[4]))


class FinalLayer(nn.Module):
    """adaLN (shift, scale), LayerNorm, modulate, Linear to the action width."""

    def __init__(self, d: int, a: int):
        super().__init__()
        self.linear = nn.Linear(d, a)
        self.adaLN_modulation = nn.Sequential(nn.SiLU(), nn.Linear(d, 2 * d))

    def forward(self, x: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
        shift, scale = self.adaLN_modulation(c).chunk(2, dim=1)
        return self.linear(modulate(_ln(x), shift, scale))


class ImagePolicy(nn.Module):
    """What every architecture shares: one encoder per camera under ``obs_encoder.<camera>``
    and the condition they make with the normalized state. ``cfg`` is the ``model`` object of a
    checkpoint's ``config.json`` (the Rust ``ModelConfig``); subclasses add the denoiser and
    ``condition`` / ``denoise``."""

    def __init__(self, cfg: Dict[str, Any]):
        super().__init__()
        self.cfg = dict(cfg)
        self.obs_encoder = nn.ModuleDict({
            camera_short_name(k): ObsEncoder(cfg["resnet_width"], cfg["keypoints"], cfg["feature_dim"])
            for k in cfg["cameras"]
        })
        if len(self.obs_encoder) != len(cfg["cameras"]):
            raise ValueError(f"cameras {cfg['cameras']} share a weight prefix")
        # Checkpoints written before `image_range` existed saw pixels in [0, 1].
        self.register_buffer("pixels", pixel_table(cfg.get("image_range", "unit")), persistent=False)

    def initialize_encoders(self, generator: Optional[torch.Generator] = None) -> None:
        """torchvision's initialisation of the trunks (kaiming-normal fan-out convolutions,
        GroupNorm 1 / 0); PyTorch's defaults for the keypoint conv and the encoder Linear."""
        g = generator
        with torch.no_grad():
            for name, m in self.obs_encoder.named_modules():
                if isinstance(m, nn.Conv2d) and ".backbone." in f".{name}.":
                    std = math.sqrt(2.0 / (m.out_channels * m.kernel_size[0] * m.kernel_size[1]))
                    m.weight.copy_(torch.randn(m.weight.shape, generator=g) * std)
                elif isinstance(m, nn.GroupNorm):
                    m.weight.fill_(1.0)
                    m.bias.fill_(0.0)
                elif isinstance(m, (nn.Conv2d, nn.Linear)):
                    fan_in = m.weight[0].numel()
                    bound = 1.0 / math.sqrt(fan_in)
                    m.weight.copy_(torch.rand(m.weight.shape, generator=g) * 2 * bound - bound)
                    m.bias.copy_(torch.rand(m.bias.shape, generator=g) * 2 * bound - bound)

    @classmethod
    def from_checkpoint(cls, path: str, weights: str = "model.safetensors",
                        device: Any = "cpu") -> "ImagePolicy":
        """The module of checkpoint directory ``path`` (its ``config.json``: ScaleDP or DP-T,
        whichever class this is called on) with the weights of ``weights`` there (the EMA
        weights by default), in eval mode."""
        from safetensors.torch import load_file

        with open(os.path.join(path, "config.json")) as f:
            cfg = json.load(f)
        policy = build_policy(cfg["model"])
        policy.load_state_dict(load_file(os.path.join(path, weights)), strict=True)
        return policy.to(device).eval()

    @property
    def cond_dim(self) -> int:
        """Condition width: (features x cameras + S) x To."""
        c = self.cfg
        return (c["feature_dim"] * len(c["cameras"]) + c["state_dim"]) * c["obs_horizon"]

    def crop(self, images: torch.Tensor, offsets: Optional[torch.Tensor] = None) -> torch.Tensor:
        """uint8 ``[N, 3, H, W]`` -> float ``[N, 3, h, w]`` in the model's pixel range: the
        window at ``offsets`` ``[N, 2]`` (top, left) per image, or the centred one."""
        cw, ch = crop_size(self.cfg)
        n, _, h, w = images.shape
        if offsets is None:
            t, left = _centre(h - ch), _centre(w - cw)
            out = images[..., t:t + ch, left:left + cw]
        else:
            offsets = offsets.to(images.device)
            rows = offsets[:, :1] + torch.arange(ch, device=images.device)
            cols = offsets[:, 1:] + torch.arange(cw, device=images.device)
            idx = torch.arange(n, device=images.device)[:, None, None]
            out = images[idx, :, rows[:, :, None], cols[:, None, :]].permute(0, 3, 1, 2)
        # Contiguous NCHW: a channels-last input crashed torch 2.10's CPU convolution backward
        # (heap corruption at 288x216).
        return self.pixels[out.long()].contiguous()

    def encode(self, images: torch.Tensor, state: torch.Tensor,
               crops: Optional[torch.Tensor] = None) -> torch.Tensor:
        """The condition ``[B, cond_dim]`` of ``images`` uint8 ``[B, To, cams, 3, H, W]`` and the
        normalized ``state`` ``[B, To, S]``; ``crops`` ``[cams, B, To, 2]`` are the windows'
        (top, left) (None: centred, as at inference)."""
        b, to = state.shape[:2]
        feats = []
        for i, key in enumerate(self.cfg["cameras"]):
            off = None if crops is None else crops[i].reshape(b * to, 2)
            x = self.crop(images[:, :, i].reshape(b * to, *images.shape[3:]), off)
            feats.append(self.obs_encoder[camera_short_name(key)](x))
        feats.append(state.reshape(b * to, -1).to(torch.float32))
        return torch.cat(feats, dim=1).reshape(b, -1)

    def condition(self, t: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        """What the denoiser computes once per DDIM step from the timesteps and the condition."""
        raise NotImplementedError

    def denoise(self, x: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
        """The predicted noise of ``x`` ``[B, C, A]`` under a precomputed condition."""
        raise NotImplementedError

    def forward(self, x: torch.Tensor, t: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        """The predicted noise of noisy actions ``x`` ``[B, C, A]`` at timesteps ``t`` ``[B]``."""
        return self.denoise(x, self.condition(t, cond))


def sin_cos(rows: int, d: int) -> torch.Tensor:
    """DiT's ``get_1d_sincos_pos_embed``: row p is ``[sin(p·ω), cos(p·ω)]``, ω_i = 10000^(−2i/d)."""
    omega = 1.0 / 10000 ** (torch.arange(d // 2, dtype=torch.float64) / (d / 2.0))
    a = torch.arange(rows, dtype=torch.float64)[:, None] * omega[None, :]
    return torch.cat([a.sin(), a.cos()], dim=1).float()


class ScaleDPPolicy(ImagePolicy):
    """The encoders, and the DiT denoiser's modules at the top level. A fresh module is
    initialised as DiT (adaLN-Zero: the untrained denoiser outputs exactly 0) and the trunks as
    torchvision. (``ScaleDPPolicy.from_checkpoint`` of a DP-T checkpoint gives a
    :class:`scaledp_data.policy.DPTPolicy`.)"""

    def __init__(self, cfg: Dict[str, Any]):
        super().__init__(cfg)
        d, a, c = cfg["hidden"], cfg["action_dim"], cfg["action_chunk"]
        self.x_embedder = nn.Linear(a, d)
        # ``pos_embed: sin_cos``: DiT's fixed table, never trained (as the Rust trainer has it).
        self.fixed_pos = cfg.get("pos_embed", "learned") == "sin_cos"
        self.pos_embed = nn.Parameter(torch.zeros(1, c, d), requires_grad=not self.fixed_pos)
        self.t_embedder = TimestepEmbedder(d)
        self.cond_obs_emb = nn.Linear(self.cond_dim, d)
        causal = cfg.get("attention", "non_causal") == "causal"
        self.blocks = nn.ModuleList(
            [Block(d, cfg["heads"], cfg["mlp_ratio"], causal) for _ in range(cfg["depth"])])
        self.final_layer = FinalLayer(d, a)
        self.initialize()

    def initialize(self, generator: Optional[torch.Generator] = None) -> None:
        """DiT's initialisation of the denoiser (xavier-uniform linears, zero biases, N(0, 0.02)
        for ``pos_embed``, ``cond_obs_emb`` and the timestep MLP, every adaLN linear and the
        final linear zeroed), after the encoders'."""
        g = generator

        def normal(t: torch.Tensor, std: float) -> None:
            with torch.no_grad():
                t.copy_(torch.randn(t.shape, generator=g) * std)

        self.initialize_encoders(g)
        with torch.no_grad():
            for name, m in self.named_modules():
                if isinstance(m, nn.Linear) and not name.startswith("obs_encoder"):
                    bound = math.sqrt(6.0 / (m.in_features + m.out_features))
                    m.weight.copy_(torch.rand(m.weight.shape, generator=g) * 2 * bound - bound)
                    m.bias.zero_()
            normal(self.pos_embed, 0.02)  # drawn either way: later tensors start alike
            if self.fixed_pos:
                self.pos_embed.copy_(sin_cos(*self.pos_embed.shape[1:]).unsqueeze(0))
            for lin in (self.cond_obs_emb, self.t_embedder.mlp[0], self.t_embedder.mlp[2]):
                normal(lin.weight, 0.02)
            for blk in self.blocks:
                blk.adaLN_modulation[1].weight.zero_()
                blk.adaLN_modulation[1].bias.zero_()
            self.final_layer.adaLN_modulation[1].weight.zero_()
            self.final_layer.adaLN_modulation[1].bias.zero_()
            self.final_layer.linear.weight.zero_()
            self.final_layer.linear.bias.zero_()

    def condition(self, t: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        """The adaLN condition ``t_emb + cond_emb`` ``[B, d]``."""
        return self.t_embedder(t) + self.cond_obs_emb(cond)

    def denoise(self, x: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
        """The predicted noise of ``x`` ``[B, C, A]`` under a precomputed condition."""
        h = self.x_embedder(x) + self.pos_embed
        for block in self.blocks:
            h = block(h, c)
        return self.final_layer(h, c)


def policy_class(cfg: Dict[str, Any]) -> type:
    """The module class of a ``model`` config: ScaleDP, or DP-T (``arch: dp_t``)."""
    arch = cfg.get("arch", "scale_dp")
    if arch == "scale_dp":
        return ScaleDPPolicy
    if arch == "dp_t":
        from .dpt import DPTPolicy

        return DPTPolicy
    raise ValueError(f"model arch {arch!r}: scale_dp or dp_t")


def build_policy(cfg: Dict[str, Any]) -> ImagePolicy:
    """A fresh module of either architecture for a ``model`` config."""
    return policy_class(cfg)(cfg)
