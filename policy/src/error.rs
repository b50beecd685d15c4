//! The crate's error type: every message names the file, batch or input and what is wrong.

use std::path::PathBuf;

/// What went wrong building, training, saving, loading or running a policy.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A tensor operation failed (a shape bug, or the device refused).
    #[error("tensor: {0}")]
    Tensor(#[from] candle_core::Error),
    /// The dataset loader failed.
    #[error(transparent)]
    Data(#[from] scaledp_datasets::Error),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A checkpoint file is missing, malformed, or does not fit the model.
    #[error("{path}: {reason}")]
    Checkpoint {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// The configuration (options, model sizes) is inconsistent.
    #[error("{0}")]
    Config(String),
    /// A checkpoint does not fit the dataset or observation it is used with.
    #[error(transparent)]
    Mismatch(Box<Mismatch>),
    /// An observation passed to [`crate::Policy::predict`] has the wrong size.
    #[error("observation: {0}")]
    Observation(String),
    /// A batch holds a value that is not finite; the step is refused.
    #[error("non-finite {what} in the batch at episode {episode} frame {frame}: step refused")]
    NonFinite {
        /// Which input (`state`, `action`).
        what: &'static str,
        /// The sample's episode.
        episode: i64,
        /// The sample's current frame.
        frame: i64,
    },
    /// Training diverged: the loss is not finite.
    #[error("step {step}: the loss is {loss}; training stopped (lower --lr or set --grad-clip)")]
    Diverged {
        /// The step.
        step: u64,
        /// The loss.
        loss: f32,
    },
    /// The trainer was asked to stop (Ctrl-C); the last checkpoint stands.
    #[error("stopped at step {step}")]
    Interrupted {
        /// The last completed step.
        step: u64,
    },
}

/// What differs between a checkpoint and the data it is used with.
#[derive(Debug, thiserror::Error)]
#[error("{what} mismatch: the checkpoint {checkpoint} has {expected}, the {other} has {found}")]
pub struct Mismatch {
    /// What differs (`cameras`, `state dimension`, ...).
    pub what: String,
    /// The checkpoint directory.
    pub checkpoint: String,
    /// What the checkpoint expects.
    pub expected: String,
    /// Where the other value comes from (`dataset datasets/cups`).
    pub other: String,
    /// What it has.
    pub found: String,
}

/// `Result` with this crate's [`Error`].
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
    pub(crate) fn checkpoint(path: impl std::fmt::Display, reason: impl std::fmt::Display) -> Self {
        Error::Checkpoint {
            path: path.to_string(),
            reason: reason.to_string(),
        }
    }
}
