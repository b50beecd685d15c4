//! What the loss averages over ([`LossSpec`], a training option) and where a step's time went
//! ([`Phases`]): shared by the trainer's loss and the CPU engine's step.

use scaledp_datasets::Batch;
use serde::{Deserialize, Serialize};

/// What the loss averages over.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct LossSpec {
    /// (timestep, noise) draws per encoded observation: the encoders run once per sample, the
    /// denoiser this many times (1: the paper's training).
    pub noise_samples: usize,
    /// Leave action steps past the episode's end out of the loss (default: train on them —
    /// they repeat the last action, so the policy learns to hold still at the end).
    pub mask_padding: bool,
}

impl LossSpec {
    /// What the batch's summed squared error is divided by: the action values the loss counts
    /// (padded steps left out when masked) times the noise draws.
    pub(crate) fn denominator(&self, batch: &Batch, action_dim: usize) -> f64 {
        let steps = if self.mask_padding {
            batch.action_is_pad.iter().filter(|p| !**p).count()
        } else {
            batch.action_is_pad.len()
        };
        (steps.max(1) * action_dim * self.noise_samples.max(1)) as f64
    }
}

impl Default for LossSpec {
    fn default() -> Self {
        LossSpec {
            noise_samples: 1,
            mask_padding: false,
        }
    }
}

/// Where a step's time went (s), summed over its micro-batches.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Phases {
    /// Cropping the images and the encoders' forward passes.
    pub encode_s: f64,
    /// The denoiser's forward pass and the loss.
    pub denoise_s: f64,
    /// The backward pass (and summing micro-batch gradients).
    pub backward_s: f64,
}
