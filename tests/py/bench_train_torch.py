"""PyTorch side of the training benchmark: the wheel's module (scaledp_data.policy, the one
PyTorch definition: ScaleDP or DP-T, as the config says), from the same initial weights, timed
on the same number of threads.

    PYTHONPATH=<unpacked wheel> python bench_train_torch.py CONFIG.json WEIGHTS.safetensors \
        --batch 64 --steps 5 --warmup 3 --threads 2

CONFIG.json is a checkpoint-style config (`{"model": {...}}`). Each step is the trainer's
(scaledp_data.policy.trainer): random crops of the uint8 images, the encoders once, the
epsilon-MSE at `--noise-samples` random timesteps per observation of the cosine schedule over
every action step, backward, AdamW (lr 1e-4, betas 0.9/0.95, the Rust trainer's parameter groups: 1e-3 on the denoiser's Linear weights, 1e-6 on
every encoder tensor). The batch is synthetic (data loading is measured on the Rust side).
Prints one JSON line: per-step seconds of the timed steps, those of the `--warmup` steps before
them (reported apart: the first allocates, and the next two still run 20-40 % slower while the
allocator and oneDNN's primitive cache fill) and samples/s. Without torch, or without the module, it prints `{"error": "..."}`.
"""

import argparse
import json
import os
import sys
import time

try:
    import torch
    from safetensors.torch import load_file

    from scaledp_data.policy import DenoisingLoss, Draws, NoiseScheduler, build_policy
    from scaledp_data.policy.options import default_options
    from scaledp_data.policy.trainer import param_groups
except ImportError as e:
    print(json.dumps({"error": f"{e.name or e} not installed"}))
    sys.exit(0)


def main():
    """Times the steps and prints the report."""
    ap = argparse.ArgumentParser()
    ap.add_argument("config")
    ap.add_argument("weights")
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--warmup", type=int, default=3, help="untimed steps first")
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--noise-samples", type=int, default=1, help="(timestep, noise) draws per encoded observation")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    with open(args.config) as f:
        cfg = json.load(f)["model"]
    policy = build_policy(cfg)  # ScaleDP or DP-T (dropout on: a training step)
    policy.load_state_dict(load_file(args.weights), strict=True)
    policy.train()
    o = default_options()
    opt = torch.optim.AdamW(param_groups(policy, o), lr=1e-4, betas=(0.9, 0.95), eps=1e-8)
    sched = NoiseScheduler(100)
    loss_fn = DenoisingLoss(policy, sched)
    g = torch.Generator().manual_seed(0)
    b, to, c, a = args.batch, cfg["obs_horizon"], cfg["action_chunk"], cfg["action_dim"]
    cams, h, w = len(cfg["cameras"]), cfg["image_height"], cfg["image_width"]
    images = torch.randint(0, 256, (b, to, cams, 3, h, w), dtype=torch.uint8, generator=g)
    state = torch.rand((b, to, cfg["state_dim"]), generator=g) * 2 - 1
    action = torch.rand((b, c, a), generator=g) * 2 - 1
    pad = torch.zeros((b, c), dtype=torch.bool)
    times = []
    for _ in range(args.warmup + args.steps):
        t0 = time.perf_counter()
        d = Draws.random(cfg, b, args.noise_samples, sched.train_steps, g)
        loss = loss_fn(images, state, action, pad, d.crops, d.timesteps, d.noise) / (
            b * c * a * max(1, args.noise_samples))
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        times.append(time.perf_counter() - t0)
    warm, steady = times[: args.warmup], times[args.warmup :]
    mean = sum(steady) / max(len(steady), 1)
    print(json.dumps({
        "warmup_step_s": warm,
        "step_s": steady,
        "mean_step_s": mean,
        "samples_per_s": b / mean if mean > 0 else None,
        "threads": args.threads,
        "torch": torch.__version__,
    }))


if __name__ == "__main__":
    main()
