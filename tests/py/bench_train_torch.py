"""PyTorch side of the training benchmark: the same ScaleDP model (tests/py/scaledp_torch.py),
from the same initial weights, timed on the same number of threads.

    python bench_train_torch.py CONFIG.json WEIGHTS.safetensors --batch 64 --steps 5 --threads 2

CONFIG.json is a checkpoint-style config (`{"model": {...}}`). Each step: random crop of
uint8 images, the encoders once, ε-MSE at `--noise-samples` random timesteps per observation
of the cosine schedule, backward, AdamW
(lr 1e-4, betas 0.9/0.95, weight decay 1e-3 on weight matrices). The batch is synthetic (data
loading is measured on the Rust side). Prints one JSON line: per-step seconds (the first step,
which allocates, is reported apart) and samples/s. Without torch it prints
`{"error": "torch not installed"}`.
"""

import argparse
import json
import math
import os
import sys
import time

try:
    import torch
except ImportError:
    print(json.dumps({"error": "torch not installed"}))
    sys.exit(0)

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from scaledp_torch import ScaleDPPolicy  # noqa: E402


def alphas_cumprod(n=100):
    ab = lambda t: math.cos((t + 0.008) / 1.008 * math.pi / 2) ** 2
    betas = torch.tensor([min(1 - ab((i + 1) / n) / ab(i / n), 0.999) for i in range(n)], dtype=torch.float32)
    return torch.cumprod(1.0 - betas, dim=0)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("config")
    ap.add_argument("weights")
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--noise-samples", type=int, default=1, help="(timestep, noise) draws per encoded observation")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    from safetensors.torch import load_file

    cfg = json.load(open(args.config))["model"]
    policy = ScaleDPPolicy(cfg)
    policy.load_state_dict(load_file(args.weights), strict=True)
    decay = [p for n, p in policy.named_parameters() if p.dim() >= 2 and n != "pos_embed"]
    no_decay = [p for n, p in policy.named_parameters() if not (p.dim() >= 2 and n != "pos_embed")]
    opt = torch.optim.AdamW(
        [{"params": decay, "weight_decay": 1e-3}, {"params": no_decay, "weight_decay": 0.0}],
        lr=1e-4,
        betas=(0.9, 0.95),
    )
    b, to, c, a = args.batch, cfg["obs_horizon"], cfg["action_chunk"], cfg["action_dim"]
    cams, h, w = len(cfg["cameras"]), cfg["image_height"], cfg["image_width"]
    images = torch.randint(0, 256, (b, to, cams, 3, h, w), dtype=torch.uint8)
    state = torch.randn(b, to, cfg["state_dim"])
    action = torch.rand(b, c, a) * 2 - 1
    ab = alphas_cumprod()
    times = []
    for _ in range(args.steps + 1):
        t0 = time.perf_counter()
        k = args.noise_samples
        cond = policy.encode(images, state, train=True).repeat_interleave(k, dim=0)
        x0 = action.repeat_interleave(k, dim=0)
        t = torch.randint(0, 100, (b * k,))
        noise = torch.randn_like(x0)
        s = ab[t][:, None, None]
        noisy = s.sqrt() * x0 + (1 - s).sqrt() * noise
        loss = F_mse(policy(noisy, t, cond), noise)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        times.append(time.perf_counter() - t0)
    steady = times[1:]
    mean = sum(steady) / max(len(steady), 1)
    print(json.dumps({
        "first_step_s": times[0],
        "step_s": steady,
        "mean_step_s": mean,
        "samples_per_s": b / mean if mean > 0 else None,
        "threads": args.threads,
        "torch": torch.__version__,
    }))


def F_mse(pred, target):
    return ((pred - target) ** 2).mean()


if __name__ == "__main__":
    main()
