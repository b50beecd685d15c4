"""The PyTorch side of the one-step parity test (tests/tests/torch_parity.rs): the wheel's
ScaleDP module (scaledp_data.policy) computes the loss and every gradient of one training step
from the weights, batch and random draws the Rust trainer used, and compares its gradients with
the Rust ones per parameter group.

    python torch_parity.py CASE_DIR

CASE_DIR holds model.safetensors (weights), case.safetensors (the batch and the draws),
grads.safetensors (the Rust gradients by parameter name) and case.json (model config, loss
spec, the Rust loss). Prints one JSON line: both losses and, per group, the largest absolute
gradient difference beside the largest gradient.
"""

import json
import os
import sys

import torch
from safetensors.torch import load_file

from scaledp_data.policy import DenoisingLoss, NoiseScheduler, build_policy, loss_terms

GROUPS = [
    ("encoder trunks", lambda n: n.startswith("obs_encoder.") and ".backbone." in n),
    ("encoder keypoints + linear", lambda n: n.startswith("obs_encoder.")),
    ("embedders (x, pos, t, cond)",
     lambda n: n.split(".")[0] in ("x_embedder", "pos_embed", "t_embedder", "cond_obs_emb")),
    ("attention (qkv, proj)", lambda n: ".attn." in n),
    ("mlp (fc1, fc2)", lambda n: ".mlp." in n and n.startswith("blocks.")),
    ("adaLN modulation", lambda n: n.startswith("blocks.") and "adaLN" in n),
    ("final layer", lambda n: n.startswith("final_layer.")),
    # DP-T (diffusion_policy's module names under model.).
    ("dp-t embeddings (input, pos, cond obs, cond pos)",
     lambda n: n.split(".")[:2] in (["model", "input_emb"], ["model", "pos_emb"],
                                    ["model", "cond_obs_emb"], ["model", "cond_pos_emb"])),
    ("dp-t condition MLP", lambda n: n.startswith("model.encoder.")),
    ("dp-t self-attention", lambda n: ".self_attn." in n),
    ("dp-t cross-attention", lambda n: ".multihead_attn." in n),
    ("dp-t FFN (linear1, linear2)", lambda n: ".linear1." in n or ".linear2." in n),
    ("dp-t norms, ln_f, head", lambda n: n.startswith("model.")),
]


def group(name):
    """The report group of parameter ``name``."""
    return next(g for g, match in GROUPS if match(name))


def main():
    """Runs the case in ``sys.argv[1]`` and prints the report."""
    d = sys.argv[1]
    case = json.load(open(os.path.join(d, "case.json")))
    cfg, spec = case["model"], case["loss"]
    torch.manual_seed(0)
    policy = build_policy(cfg)
    policy.load_state_dict(load_file(os.path.join(d, "model.safetensors")), strict=True)
    t = load_file(os.path.join(d, "case.safetensors"))
    pad = t["action_is_pad"].bool()
    loss_fn = DenoisingLoss(policy, NoiseScheduler(case["train_steps"]), spec["mask_padding"])
    k = max(1, spec["noise_samples"])
    denom = loss_terms(pad, cfg["action_dim"], k, spec["mask_padding"])
    total = loss_fn(t["images"], t["state"], t["action"], pad, t["crops"], t["timesteps"], t["noise"])
    loss = total / denom
    loss.backward()
    rust = load_file(os.path.join(d, "grads.safetensors"))
    groups = {}
    worst = {"name": None, "rel": -1.0}
    for name, p in policy.named_parameters():
        g, r = p.grad.reshape(-1), rust[name].reshape(-1)
        diff = float((g - r).abs().max())
        top = float(r.abs().max())
        e = groups.setdefault(group(name), {"max_abs_diff": 0.0, "max_abs_grad": 0.0, "params": 0})
        e["max_abs_diff"] = max(e["max_abs_diff"], diff)
        e["max_abs_grad"] = max(e["max_abs_grad"], top)
        e["params"] += g.numel()
        rel = diff / max(top, 1e-30)
        if rel > worst["rel"]:
            worst = {"name": name, "rel": rel, "max_abs_diff": diff, "max_abs_grad": top}
    print(json.dumps({"torch": torch.__version__, "loss_rust": case["loss_rust"],
                      "loss_torch": float(loss), "terms": denom, "groups": groups, "worst": worst}))


if __name__ == "__main__":
    main()
