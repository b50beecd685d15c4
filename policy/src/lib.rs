//! The ScaleDP policy in Rust (candle 0.11): diffusion_policy's image encoders + the ScaleDP
//! DiT denoiser (adaLN-Zero, non-causal attention over the action chunk), its DDPM/DDIM noise
//! schedule, a trainer fed by `scaledp_datasets::Loader`, checkpoints a PyTorch user can open,
//! and inference for a robot's control loop.
//!
//! # Using it
//!
//! ```no_run
//! use std::path::Path;
//! use candle_core::Device;
//! use scaledp_policy::{ModelSize, Observation, Policy, TrainOptions, Trainer};
//!
//! // Train (CPU by default; `--features cuda` for candle's CUDA backend).
//! let opts = TrainOptions::default().model(ModelSize::Ti).steps(20_000).image_size(84, 84);
//! let mut trainer = Trainer::new("datasets/cups", Path::new("runs/cups"), opts, &Device::Cpu)?;
//! trainer.run(|event| eprintln!("{event:?}"))?;
//!
//! // Act: raw observations in, un-normalized actions out.
//! let policy = Policy::load(Path::new("runs/cups"), &Device::Cpu)?; // latest checkpoint
//! let cfg = policy.config(); // cameras, image size, obs_horizon, action_chunk, names, fps, rig
//! let (w, h) = (cfg.model.image_width as usize, cfg.model.image_height as usize);
//! let obs = Observation {
//!     images: vec![0u8; cfg.model.obs_horizon * cfg.model.cameras.len() * 3 * w * h],
//!     state: vec![0.0; cfg.model.obs_horizon * cfg.model.state_dim],
//! };
//! let chunk = policy.predict(&obs, 0)?; // [C, A]: chunk.step(0) is the first action
//! # Ok::<(), scaledp_policy::Error>(())
//! ```
//!
//! # The model
//!
//! - Encoder, one per camera (diffusion_policy / robomimic `VisualCore`): crop (random per
//!   image in training, centred at inference, ratio `crop`, 0.9), /255 (no ImageNet
//!   normalization), ResNet-18 trunk with GroupNorm(C/16), SpatialSoftmax (32 keypoints → 64),
//!   Linear(64 → 64). Per observation step the camera features then the normalized state; the
//!   condition is that flattened over To.
//! - Denoiser: `x_embedder` + `pos_embed` over the C action tokens; `c = t_emb + cond_emb`;
//!   N blocks of adaLN-Zero modulated LayerNorm (no affine, eps 1e-6) → multi-head attention
//!   (fused `qkv`) and tanh-GELU MLP with gated residuals; `final_layer`. The paper's attention
//!   is non-causal ([`ModelConfig`]'s default, and the `paper` preset's); a training run's
//!   default is causal ([`default_attention`] says why).
//! - Sizes [`ModelSize`]: ti 8/256/4, s 12/384/6, b 12/768/12, l 24/1024/16, h 32/1280/16.
//!   [`model::ScaleDp::count`] gives the parameter counts from shapes alone.
//!
//! # Weight names (`model.safetensors`)
//!
//! PyTorch state-dict names, PyTorch layouts (Linear `[out, in]`, Conv `[out, in, kh, kw]`):
//! `x_embedder.{weight,bias}`, `pos_embed`, `t_embedder.mlp.{0,2}.*`, `cond_obs_emb.*`,
//! `blocks.{i}.attn.{qkv,proj}.*`, `blocks.{i}.mlp.{fc1,fc2}.*`,
//! `blocks.{i}.adaLN_modulation.1.*`, `final_layer.{linear,adaLN_modulation.1}.*`, and per
//! camera `obs_encoder.<camera>.backbone.*` (torchvision ResNet names: `conv1`, `bn1`,
//! `layer{1..4}.{0,1}.{conv1,bn1,conv2,bn2}`, `layer{2..4}.0.downsample.{0,1}`; the GroupNorms
//! keep the BatchNorms' names), `obs_encoder.<camera>.pool.nets.*` (keypoint 1×1 conv) and
//! `obs_encoder.<camera>.linear.*`, where `<camera>` is the key without `observation.images.`
//! (dots as underscores). `scaledp_data.policy` (the wheel, `python/`) holds the PyTorch module
//! that loads it with `load_state_dict(strict=True)`; `tests/py/scaledp_reference.py` an
//! independent numpy forward pass the tests compare against.
//!
//! # Diffusion and training
//!
//! [`NoiseScheduler`]: DDPM, 100 steps, `squaredcos_cap_v2`, ε-prediction; DDIM 10 steps, η 0,
//! leading spacing (90 … 0), `set_alpha_to_one`, x̂₀ clipped to [−1, 1] ([`ddim_sample`]).
//! Loss: MSE masked by `action_is_pad` (Σ over valid steps / (valid steps · A)). [`Trainer`]:
//! AdamW (lr 1e-4, betas 0.9/0.95, weight decay 1e-3 on Linear/Conv weights only), diffusers'
//! cosine schedule with 500 warm-up steps, diffusion_policy's EMA (power 0.75, max 0.9999),
//! optional gradient clipping, micro-batches, one seed for weights, data order, crops,
//! timesteps and noise (two runs give the same losses; a resume continues them bit for bit).
//! A checkpoint is `checkpoints/step_N/` with `model.safetensors` (EMA), `train_state.safetensors`
//! and `config.json` ([`CheckpointConfig`]); every step is a line of `metrics.jsonl`.
//!
//! # Devices and speed
//!
//! CPU by default. The `cuda` feature forwards to candle's CUDA backend (needs nvcc to build;
//! CI builds CPU only); on CUDA, convolutions, GroupNorm and the optimizer use candle's own
//! ops. On the CPU, candle's conv2d backward (a `conv_transpose2d` without GEMM), composed
//! GroupNorm (~12 allocating passes) and max-pool (no backward for a 3×3/2 pool) dominated a
//! training step, so the crate has fused CPU kernels with their own backward passes for
//! convolution (im2col + GEMM), GroupNorm(+ReLU) and the stem's max-pool, an in-place AdamW
//! and EMA, and enables gemm's AVX-512 kernels.

pub mod bench;
mod checkpoint;
mod config;
mod engine;
mod error;
pub mod flops;
mod image_chain;
mod inference;
pub mod model;
pub mod parity;
mod predict;
mod scheduler;
mod trainer;

pub use checkpoint::{
    list as list_checkpoints, resolve as resolve_checkpoint, CheckpointConfig, Normalization,
    NormalizerConfig,
};
pub use config::{
    Architecture, Attention, DiffusionConfig, ImageRange, ModelConfig, ModelSize, PosEmbed,
    DPT_DIMS, DPT_DROPOUT,
};
pub use error::{Error, Mismatch, Result};
pub use image_chain::{ImageChain, StoredImages, TrainResize, DEFAULT_JPEG_QUALITY};
pub use inference::{ddim_sample, ActionChunk, Observation, Policy};
pub use model::cpu::init_threads;
pub use predict::{predict_episode, EpisodePrediction};
pub use scheduler::NoiseScheduler;
pub use trainer::{
    cosine_lr, default_attention, AdamWConfig, EmaConfig, Event, LossSpec, Phases, StateNorm,
    StepRecord, Summary, TrainOptions, Trainer, ValRecord, PRESETS,
};
