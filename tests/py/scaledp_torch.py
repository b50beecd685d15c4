"""The reference PyTorch module of the Rust ScaleDP policy (`policy/` crate): its state dict has
exactly the names of a checkpoint's `model.safetensors`, so

    policy = ScaleDPPolicy.from_checkpoint("runs/cups/checkpoints/step_00010000")

loads with `load_state_dict(strict=True)`. Only torch is needed (torchvision is not: the
ResNet-18 trunk is written out with torchvision's module names, BatchNorm replaced by
GroupNorm(C/16) as diffusion_policy's `replace_bn_with_gn` does).

Used by `tests/py/bench_train_torch.py` (the PyTorch side of the training benchmark).
"""

import json
import math
import os

import torch
import torch.nn as nn
import torch.nn.functional as F


def gn(c):
    return nn.GroupNorm(max(1, c // 16), c)


class BasicBlock(nn.Module):
    def __init__(self, c_in, c_out, stride):
        super().__init__()
        self.conv1 = nn.Conv2d(c_in, c_out, 3, stride, 1, bias=False)
        self.bn1 = gn(c_out)
        self.conv2 = nn.Conv2d(c_out, c_out, 3, 1, 1, bias=False)
        self.bn2 = gn(c_out)
        self.downsample = None
        if stride != 1 or c_in != c_out:
            self.downsample = nn.Sequential(nn.Conv2d(c_in, c_out, 1, stride, bias=False), gn(c_out))

    def forward(self, x):
        y = F.relu(self.bn1(self.conv1(x)))
        y = self.bn2(self.conv2(y))
        skip = x if self.downsample is None else self.downsample(x)
        return F.relu(y + skip)


class ResNet18Trunk(nn.Module):
    """torchvision resnet18 `children()[:-2]` (no avgpool, no fc) with GroupNorm."""

    def __init__(self, width=64):
        super().__init__()
        self.conv1 = nn.Conv2d(3, width, 7, 2, 3, bias=False)
        self.bn1 = gn(width)
        c = width
        for i, mult in enumerate([1, 2, 4, 8]):
            stride = 1 if i == 0 else 2
            layer = nn.Sequential(BasicBlock(c, width * mult, stride), BasicBlock(width * mult, width * mult, 1))
            setattr(self, f"layer{i + 1}", layer)
            c = width * mult

    def forward(self, x):
        x = F.max_pool2d(F.relu(self.bn1(self.conv1(x))), 3, 2, 1)
        for i in range(4):
            x = getattr(self, f"layer{i + 1}")(x)
        return x


class SpatialSoftmax(nn.Module):
    """robomimic's SpatialSoftmax: 1x1 conv to keypoints, softmax, expected (x, y)."""

    def __init__(self, c_in, keypoints=32):
        super().__init__()
        self.nets = nn.Conv2d(c_in, keypoints, 1)
        self.keypoints = keypoints

    def forward(self, x):
        x = self.nets(x)
        n, k, h, w = x.shape
        pos_x, pos_y = torch.meshgrid(
            torch.linspace(-1.0, 1.0, w, device=x.device, dtype=x.dtype),
            torch.linspace(-1.0, 1.0, h, device=x.device, dtype=x.dtype),
            indexing="xy",
        )
        att = F.softmax(x.reshape(n * k, h * w), dim=-1)
        xy = torch.stack([att @ pos_x.reshape(-1), att @ pos_y.reshape(-1)], dim=1)
        return xy.reshape(n, 2 * k)


class ObsEncoder(nn.Module):
    def __init__(self, width=64, keypoints=32, feature_dim=64):
        super().__init__()
        self.backbone = ResNet18Trunk(width)
        self.pool = SpatialSoftmax(8 * width, keypoints)
        self.linear = nn.Linear(2 * keypoints, feature_dim)

    def forward(self, x):
        return self.linear(self.pool(self.backbone(x)))


def modulate(x, shift, scale):
    return x * (1 + scale.unsqueeze(1)) + shift.unsqueeze(1)


class TimestepEmbedder(nn.Module):
    def __init__(self, d, freq=256):
        super().__init__()
        self.mlp = nn.Sequential(nn.Linear(freq, d), nn.SiLU(), nn.Linear(d, d))
        self.freq = freq

    def forward(self, t):
        half = self.freq // 2
        freqs = torch.exp(-math.log(10000) * torch.arange(half, dtype=torch.float32, device=t.device) / half)
        args = t[:, None].float() * freqs[None]
        return self.mlp(torch.cat([torch.cos(args), torch.sin(args)], dim=-1))


class Attention(nn.Module):
    def __init__(self, d, heads, causal=False):
        super().__init__()
        self.heads = heads
        self.causal = causal
        self.qkv = nn.Linear(d, 3 * d)
        self.proj = nn.Linear(d, d)

    def forward(self, x):
        b, n, d = x.shape
        qkv = self.qkv(x).reshape(b, n, 3, self.heads, d // self.heads).permute(2, 0, 3, 1, 4)
        # ScaleDP: no mask (non-causal); the ablation: token i sees tokens <= i.
        y = F.scaled_dot_product_attention(qkv[0], qkv[1], qkv[2], is_causal=self.causal)
        return self.proj(y.transpose(1, 2).reshape(b, n, d))


class Mlp(nn.Module):
    def __init__(self, d, hidden):
        super().__init__()
        self.fc1 = nn.Linear(d, hidden)
        self.fc2 = nn.Linear(hidden, d)

    def forward(self, x):
        return self.fc2(F.gelu(self.fc1(x), approximate="tanh"))


class Block(nn.Module):
    def __init__(self, d, heads, mlp_ratio=4, causal=False):
        super().__init__()
        self.attn = Attention(d, heads, causal)
        self.mlp = Mlp(d, mlp_ratio * d)
        self.adaLN_modulation = nn.Sequential(nn.SiLU(), nn.Linear(d, 6 * d))

    def forward(self, x, c):
        m = self.adaLN_modulation(c).chunk(6, dim=1)
        ln = lambda v: F.layer_norm(v, v.shape[-1:], eps=1e-6)
        x = x + m[2].unsqueeze(1) * self.attn(modulate(ln(x), m[0], m[1]))
        return x + m[5].unsqueeze(1) * self.mlp(modulate(ln(x), m[3], m[4]))


class FinalLayer(nn.Module):
    def __init__(self, d, a):
        super().__init__()
        self.linear = nn.Linear(d, a)
        self.adaLN_modulation = nn.Sequential(nn.SiLU(), nn.Linear(d, 2 * d))

    def forward(self, x, c):
        shift, scale = self.adaLN_modulation(c).chunk(2, dim=1)
        return self.linear(modulate(F.layer_norm(x, x.shape[-1:], eps=1e-6), shift, scale))


class ScaleDPPolicy(nn.Module):
    """Encoders under `obs_encoder.<camera>`, the denoiser's modules at the top level."""

    def __init__(self, cfg):
        super().__init__()
        self.cfg = cfg
        d, a, c = cfg["hidden"], cfg["action_dim"], cfg["action_chunk"]
        self.obs_encoder = nn.ModuleDict(
            {short(k): ObsEncoder(cfg["resnet_width"], cfg["keypoints"], cfg["feature_dim"]) for k in cfg["cameras"]}
        )
        cond = (cfg["feature_dim"] * len(cfg["cameras"]) + cfg["state_dim"]) * cfg["obs_horizon"]
        self.x_embedder = nn.Linear(a, d)
        self.pos_embed = nn.Parameter(torch.zeros(1, c, d))
        self.t_embedder = TimestepEmbedder(d)
        self.cond_obs_emb = nn.Linear(cond, d)
        causal = cfg.get("attention", "non_causal") == "causal"
        self.blocks = nn.ModuleList([Block(d, cfg["heads"], cfg["mlp_ratio"], causal) for _ in range(cfg["depth"])])
        self.final_layer = FinalLayer(d, a)

    @classmethod
    def from_checkpoint(cls, path, weights="model.safetensors"):
        from safetensors.torch import load_file

        cfg = json.load(open(os.path.join(path, "config.json")))
        policy = cls(cfg["model"])
        policy.load_state_dict(load_file(os.path.join(path, weights)), strict=True)
        return policy

    def crop(self, images, train):
        """uint8 [N, 3, H, W] -> float [N, 3, h, w] in the model's pixel range ([-1, 1], or [0, 1]
        for `image_range: unit`): random (per image) or centre crop."""
        cfg = self.cfg
        ch = min(max(round(cfg["image_height"] * cfg["crop"]), 1), cfg["image_height"])
        cw = min(max(round(cfg["image_width"] * cfg["crop"]), 1), cfg["image_width"])
        h, w = images.shape[-2:]
        if train:
            tops = torch.randint(0, h - ch + 1, (images.shape[0],))
            lefts = torch.randint(0, w - cw + 1, (images.shape[0],))
            images = torch.stack([im[:, t : t + ch, l : l + cw] for im, t, l in zip(images, tops, lefts)])
        else:
            t, l = int(round((h - ch) / 2.0)), int(round((w - cw) / 2.0))
            images = images[..., t : t + ch, l : l + cw]
        if self.cfg.get("image_range", "unit") == "symmetric":
            return images.float() / 255.0 * 2.0 - 1.0
        return images.float() / 255.0

    def encode(self, images, state, train=False):
        """images uint8 [B, To, cams, 3, H, W], state normalized [B, To, S] -> [B, cond]."""
        b, to = state.shape[:2]
        feats = []
        for i, key in enumerate(self.cfg["cameras"]):
            x = self.crop(images[:, :, i].reshape(b * to, *images.shape[3:]), train)
            feats.append(self.obs_encoder[short(key)](x))
        feats.append(state.reshape(b * to, -1))
        return torch.cat(feats, dim=1).reshape(b, -1)

    def forward(self, x, t, cond):
        c = self.t_embedder(t) + self.cond_obs_emb(cond)
        h = self.x_embedder(x) + self.pos_embed
        for block in self.blocks:
            h = block(h, c)
        return self.final_layer(h, c)


def short(key):
    s = key[len("observation.images.") :] if key.startswith("observation.images.") else key
    return s.replace(".", "_")
