//! ScaleDP in Rust (work in progress).

mod checkpoint;
mod config;
mod error;
mod inference;
pub mod model;
mod predict;
mod scheduler;
mod trainer;

pub use checkpoint::{CheckpointConfig, Normalization, NormalizerConfig};
pub use config::{DiffusionConfig, ModelConfig, ModelSize};
pub use error::{Error, Result};
pub use inference::{ddim_sample, ActionChunk, Observation, Policy};
pub use predict::{predict_episode, EpisodePrediction};
pub use scheduler::NoiseScheduler;
pub use trainer::{
    cosine_lr, AdamWConfig, EmaConfig, Event, StepRecord, Summary, TrainOptions, Trainer,
    ValRecord,
};
