"""The ScaleDP policy (and DP-T, the paper's baseline) in PyTorch (needs torch and safetensors: ``pip install
scaledp-data[torch]``): the same network, noise schedule, loss and checkpoint format as the Rust
policy (``scaledp train`` / ``serve`` / ``eval``), so a checkpoint moves freely between the two.

    from scaledp_data.policy import ScaleDPPolicy, NoiseScheduler, ddim_sample

    policy = ScaleDPPolicy.from_checkpoint("runs/cube/checkpoints/step_00010000")
    sched = NoiseScheduler(100)
    sched.set_timesteps(10)
    cond = policy.encode(images, state)              # uint8 [B, To, cams, 3, H, W], normalized state
    chunk = ddim_sample(policy, sched, cond)          # normalized actions [B, C, A]

``python -m scaledp_data.train`` trains it, in one process or under ``torchrun`` (DDP).
"""

from .checkpoint import read_config, resolve
from .diffusion import DenoisingLoss, Draws, NoiseScheduler, ddim_sample, loss_terms
from .dpt import DPTPolicy
from .model import ImagePolicy, ScaleDPPolicy, build_policy, camera_short_name, crop_size

__all__ = ["ScaleDPPolicy", "DPTPolicy", "ImagePolicy", "build_policy", "NoiseScheduler", "ddim_sample", "Draws", "DenoisingLoss",
           "loss_terms", "crop_size", "camera_short_name", "read_config", "resolve"]
