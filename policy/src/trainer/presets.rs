//! Named training recipes: settings a user picks by name (`scaledp train --preset NAME`) and
//! overrides flag by flag. Each says what it changes against the defaults, which are the
//! paper's except ScaleDP's causal attention; `paper` is the paper's configuration whole.

use crate::config::Attention;
use crate::trainer::options::TrainOptions;

/// The presets' names.
pub const PRESETS: [&str; 4] = ["paper", "cpu-sim", "cpu-metaworld", "cpu-aloha"];

/// The paper's ScaleDP: the defaults with its non-causal attention over the action chunk, which
/// was the default until 2026-12-07 (see [`crate::default_attention`] for why it no longer is).
/// On a CPU recipe the same is one flag: `--preset cpu-aloha --attention non-causal`.
fn paper(o: TrainOptions) -> TrainOptions {
    o.attention(Attention::NonCausal)
}

/// The recipe that trains ScaleDP-Ti on the simulated cube task within three hours on two CPU
/// cores (see the README's "whole cycle"): what it changes against the paper's defaults, and
/// why, is in each line.
fn cpu_sim(o: TrainOptions) -> TrainOptions {
    o
        // ResNet-18 trunks at half width: a quarter of the encoders' FLOPs; the cube and its
        // target are plain colours on a grey table.
        .resnet_width(32)
        // Two (timestep, noise) draws per encoded observation: the encoders run once.
        .noise_samples(2)
        .batch_size(64)
        // A short run wants a larger peak learning rate and a short warm-up.
        .lr(3e-4)
        .warmup_steps(500)
        // The pilot (same settings, a 4,000-step schedule) passed 19 of 20 validation seeds at
        // step 2,000; 3,000 steps end the cosine schedule in about an hour on two cores
        // non-causal, 1.6 h causal (the default; docs/results/historical/cpu-sim/).
        .steps(3000)
        .checkpoint_every(500)
        // Every demonstration trains; checkpoints are chosen on validation seeds in closed loop.
        .val_ratio(0.0)
        .val_every(0)
}

/// The MetaWorld benchmark's one recipe (every task, both ScaleDP-Ti and DP-T): `cpu-sim` at
/// MetaWorld's 84×84 images (crops of 76×76, diffusion_policy's simulation size), fewer steps so
/// the slower arm (DP-T, about 1.15 s a step against Ti's 0.95 s on two cores) trains within the
/// hour a task and arm may take: 20 demonstrations of about 110 steps are ~2,200 samples, and
/// 2,500 steps of 64 are ~70 epochs.
fn cpu_metaworld(o: TrainOptions) -> TrainOptions {
    cpu_sim(o)
        .image_size(84, 84)
        .steps(2500)
        .checkpoint_every(500)
}

/// The ALOHA benchmark's one recipe (both tasks, every arm): `cpu-sim` at the rig's 128×96 top
/// camera (crops of 115×86), with chunks of 32 actions (0.64 s, half of them executed): 16 would
/// be a third of a second at 50 Hz, where diffusion_policy's 16 at 10 Hz span 1.6 s and ACT's
/// chunks 2 s. 2,500 steps: a step took 1.26 s (Ti), 1.73 s (DP-T) and 2.97 s (S) on two
/// cores, so Ti and DP-T train in 0.9–1.2 h and S in 2.1 h, just over the two hours a task and
/// arm may take (its transfer-cube run: 2.09 h).
/// Over 50 demonstrations of ~6–8 s at 50 Hz (~17,000 samples) that is ~9 epochs.
fn cpu_aloha(o: TrainOptions) -> TrainOptions {
    cpu_sim(o)
        .image_size(128, 96)
        .action_chunk(32)
        .steps(2500)
        .checkpoint_every(500)
}

impl TrainOptions {
    /// The options of preset `name` (see [`PRESETS`]) on top of the defaults, or `None` for an
    /// unknown name.
    pub fn preset(name: &str) -> Option<TrainOptions> {
        match name {
            "paper" => Some(paper(TrainOptions::default())),
            "cpu-sim" => Some(cpu_sim(TrainOptions::default())),
            "cpu-metaworld" => Some(cpu_metaworld(TrainOptions::default())),
            "cpu-aloha" => Some(cpu_aloha(TrainOptions::default())),
            _ => None,
        }
    }
}
