"""An independent forward pass of the ScaleDP policy in plain numpy (float64), reading the
weights from `model.safetensors` by their PyTorch state-dict names.

    python scaledp_reference.py CASE.json

CASE.json (written by policy/tests/numpy_reference.rs) names the weights file and holds the
model config and the inputs: uint8 images [B, To, cams, 3, H, W], normalized state [B, To, S],
noisy actions [B, C, A] and timesteps [B]. Prints one JSON line: the condition vectors
[B, cond_dim] (encoders + state) and the predicted noise [B, C, A].

Written from the papers and the reference modules' definitions (torchvision ResNet-18 with
GroupNorm(C/16), robomimic SpatialSoftmax, DiT adaLN-Zero blocks), not from the Rust code.
"""

import json
import math
import sys

import numpy as np
from safetensors.numpy import load_file


def conv2d(x, w, stride, padding, bias=None):
    """x [N, C, H, W], w [O, C, kh, kw] -> [N, O, H', W'] (cross-correlation, as PyTorch)."""
    x = np.pad(x, ((0, 0), (0, 0), (padding, padding), (padding, padding)))
    o, c, kh, kw = w.shape
    win = np.lib.stride_tricks.sliding_window_view(x, (kh, kw), axis=(2, 3))
    win = win[:, :, ::stride, ::stride]  # [N, C, H', W', kh, kw]
    y = np.einsum("nchwij,ocij->nohw", win, w, optimize=True)
    if bias is not None:
        y = y + bias[None, :, None, None]
    return y


def group_norm(x, weight, bias, groups, eps=1e-5):
    n, c = x.shape[:2]
    g = x.reshape(n, groups, -1)
    mean = g.mean(axis=2, keepdims=True)
    var = g.var(axis=2, keepdims=True)
    g = (g - mean) / np.sqrt(var + eps)
    x = g.reshape(x.shape)
    return x * weight[None, :, None, None] + bias[None, :, None, None]


def max_pool_3x3_s2(x):
    x = np.pad(x, ((0, 0), (0, 0), (1, 1), (1, 1)), constant_values=-np.inf)
    win = np.lib.stride_tricks.sliding_window_view(x, (3, 3), axis=(2, 3))[:, :, ::2, ::2]
    return win.max(axis=(4, 5))


def relu(x):
    return np.maximum(x, 0.0)


def resnet18(w, p, x, width):
    def gn(name, x):
        c = x.shape[1]
        return group_norm(x, w[f"{name}.weight"], w[f"{name}.bias"], max(1, c // 16))

    x = relu(gn(f"{p}.bn1", conv2d(x, w[f"{p}.conv1.weight"], 2, 3)))
    x = max_pool_3x3_s2(x)
    for stage in range(4):
        for block in range(2):
            b = f"{p}.layer{stage + 1}.{block}"
            stride = 2 if stage > 0 and block == 0 else 1
            y = relu(gn(f"{b}.bn1", conv2d(x, w[f"{b}.conv1.weight"], stride, 1)))
            y = gn(f"{b}.bn2", conv2d(y, w[f"{b}.conv2.weight"], 1, 1))
            if f"{b}.downsample.0.weight" in w:
                x = gn(f"{b}.downsample.1", conv2d(x, w[f"{b}.downsample.0.weight"], stride, 0))
            x = relu(y + x)
    return x


def spatial_softmax(w, p, x):
    maps = conv2d(x, w[f"{p}.weight"], 1, 0, w[f"{p}.bias"])
    n, k, h, wd = maps.shape
    maps = maps.reshape(n * k, h * wd)
    maps = np.exp(maps - maps.max(axis=1, keepdims=True))
    att = maps / maps.sum(axis=1, keepdims=True)
    pos_x, pos_y = np.meshgrid(np.linspace(-1.0, 1.0, wd), np.linspace(-1.0, 1.0, h))
    ex = att @ pos_x.reshape(-1)
    ey = att @ pos_y.reshape(-1)
    return np.stack([ex, ey], axis=1).reshape(n, 2 * k)


def center_crop(img, ch, cw):
    """torchvision.transforms.functional.center_crop offsets: int(round((side - crop) / 2))."""
    h, w = img.shape[-2:]
    top = int(round((h - ch) / 2.0))
    left = int(round((w - cw) / 2.0))
    return img[..., top : top + ch, left : left + cw]


def encode(w, cfg, images, state):
    b, to = state.shape[:2]
    cams = cfg["cameras"]
    cw = min(max(int(round(cfg["image_width"] * cfg["crop"])), 1), cfg["image_width"])
    ch = min(max(int(round(cfg["image_height"] * cfg["crop"])), 1), cfg["image_height"])
    feats = []
    for i, key in enumerate(cams):
        short = key[len("observation.images.") :] if key.startswith("observation.images.") else key
        p = "obs_encoder." + short.replace(".", "_")
        x = images[:, :, i].reshape(b * to, 3, cfg["image_height"], cfg["image_width"])
        x = x.astype(np.float64) / 255.0
        if cfg.get("image_range", "unit") == "symmetric":
            x = x * 2.0 - 1.0
        x = center_crop(x, ch, cw)
        f = resnet18(w, f"{p}.backbone", x, cfg["resnet_width"])
        f = spatial_softmax(w, f"{p}.pool.nets", f)
        f = f @ w[f"{p}.linear.weight"].T + w[f"{p}.linear.bias"]
        feats.append(f)
    feats.append(state.reshape(b * to, -1))
    return np.concatenate(feats, axis=1).reshape(b, -1)


def linear(w, p, x):
    return x @ w[f"{p}.weight"].T + w[f"{p}.bias"]


def silu(x):
    return x / (1.0 + np.exp(-x))


def gelu_tanh(x):
    return 0.5 * x * (1.0 + np.tanh(math.sqrt(2.0 / math.pi) * (x + 0.044715 * x**3)))


def layer_norm(x, eps=1e-6):
    mean = x.mean(axis=-1, keepdims=True)
    var = x.var(axis=-1, keepdims=True)
    return (x - mean) / np.sqrt(var + eps)


def modulate(x, shift, scale):
    return x * (1.0 + scale[:, None, :]) + shift[:, None, :]


def timestep_embedding(t, dim=256, max_period=10000.0):
    half = dim // 2
    freqs = np.exp(-math.log(max_period) * np.arange(half, dtype=np.float64) / half)
    args = t[:, None].astype(np.float64) * freqs[None]
    return np.concatenate([np.cos(args), np.sin(args)], axis=-1)


def attention(w, p, x, heads, causal=False):
    b, n, d = x.shape
    hd = d // heads
    qkv = linear(w, f"{p}.qkv", x).reshape(b, n, 3, heads, hd).transpose(2, 0, 3, 1, 4)
    q, k, v = qkv[0], qkv[1], qkv[2]
    s = (q * hd**-0.5) @ k.transpose(0, 1, 3, 2)  # ScaleDP: every token sees every token
    if causal:  # the ablation: token i sees tokens <= i
        s = np.where(np.tril(np.ones((n, n), dtype=bool)), s, -np.inf)
    s = np.exp(s - s.max(axis=-1, keepdims=True))
    a = s / s.sum(axis=-1, keepdims=True)
    y = (a @ v).transpose(0, 2, 1, 3).reshape(b, n, d)
    return linear(w, f"{p}.proj", y)


def denoise(w, cfg, x, t, cond):
    c = linear(w, "t_embedder.mlp.2", silu(linear(w, "t_embedder.mlp.0", timestep_embedding(t))))
    c = c + linear(w, "cond_obs_emb", cond)
    h = linear(w, "x_embedder", x) + w["pos_embed"]
    for i in range(cfg["depth"]):
        p = f"blocks.{i}"
        m = np.split(linear(w, f"{p}.adaLN_modulation.1", silu(c)), 6, axis=1)
        causal = cfg.get("attention", "non_causal") == "causal"
        h = h + m[2][:, None] * attention(w, f"{p}.attn", modulate(layer_norm(h), m[0], m[1]), cfg["heads"], causal)
        y = linear(w, f"{p}.mlp.fc2", gelu_tanh(linear(w, f"{p}.mlp.fc1", modulate(layer_norm(h), m[3], m[4]))))
        h = h + m[5][:, None] * y
    shift, scale = np.split(linear(w, "final_layer.adaLN_modulation.1", silu(c)), 2, axis=1)
    return linear(w, "final_layer.linear", modulate(layer_norm(h), shift, scale))


def main():
    case = json.load(open(sys.argv[1]))
    cfg = case["config"]
    w = {k: v.astype(np.float64) for k, v in load_file(case["weights"]).items()}
    b, to = case["batch"], cfg["obs_horizon"]
    cams, hh, ww = len(cfg["cameras"]), cfg["image_height"], cfg["image_width"]
    images = np.array(case["images"], dtype=np.uint8).reshape(b, to, cams, 3, hh, ww)
    state = np.array(case["state"], dtype=np.float64).reshape(b, to, cfg["state_dim"])
    x = np.array(case["x"], dtype=np.float64).reshape(b, cfg["action_chunk"], cfg["action_dim"])
    t = np.array(case["t"], dtype=np.float64)
    cond = encode(w, cfg, images, state)
    eps = denoise(w, cfg, x, t, cond)
    print(json.dumps({"cond": cond.reshape(-1).tolist(), "eps": eps.reshape(-1).tolist()}))


if __name__ == "__main__":
    main()
