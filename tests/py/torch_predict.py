"""Action chunks of a checkpoint by the wheel's PyTorch module (scaledp_data.policy): raw
observations in, raw actions out, as the Rust `Policy::predict_batch` computes them -- state
normalized with config.json's numbers, centre crops, DDIM from the given starting noise, actions
un-normalized (both in float64, as the Rust normalizer).

    python torch_predict.py CHECKPOINT CASE.safetensors

CASE holds `images` uint8 [B, To, cams, 3, H, W], `state` float32 [B, To, S] (raw) and `noise`
float32 [B, C, A]. Prints one JSON line: {"actions": [[...]] per observation, "torch": version}.
"""

import sys

import numpy as np
import torch
from safetensors.torch import load_file

from scaledp_data.policy import ImagePolicy, NoiseScheduler, ddim_sample, read_config


def main():
    """Predicts the chunks of the case and prints them."""
    ckpt, case = sys.argv[1], sys.argv[2]
    cfg = read_config(ckpt)
    policy = ImagePolicy.from_checkpoint(ckpt).eval()  # ScaleDP or DP-T, as config.json says
    t = load_file(case)
    norm = cfg["normalizer"]
    s_scale, s_off = (np.asarray(norm["state"][k], dtype=np.float64) for k in ("scale", "offset"))
    a_scale, a_off = (np.asarray(norm["action"][k], dtype=np.float64) for k in ("scale", "offset"))
    state = (t["state"].numpy().astype(np.float64) * s_scale + s_off).astype(np.float32)
    sched = NoiseScheduler(cfg["diffusion"]["train_steps"])
    sched.set_timesteps(cfg["diffusion"]["inference_steps"])
    with torch.no_grad():
        cond = policy.encode(t["images"], torch.from_numpy(state))
        x = ddim_sample(policy, sched, cond, t["noise"]).numpy()
    actions = ((x.astype(np.float64) - a_off) / a_scale).astype(np.float32)
    print(__import__("json").dumps({"actions": actions.reshape(len(actions), -1).tolist(),
                                    "torch": torch.__version__}))


if __name__ == "__main__":
    main()
