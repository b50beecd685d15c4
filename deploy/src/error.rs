//! What can go wrong between a checkpoint and a robot.

/// Deployment errors: each one line naming what is wrong and with what.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The checkpoint and the rig do not fit together (rig, cameras, dimensions, commands).
    #[error("{0}")]
    Incompatible(String),
    /// Bad options.
    #[error("{0}")]
    Options(String),
    /// The policy failed to load or to predict.
    #[error(transparent)]
    Policy(#[from] scaledp_policy::Error),
    /// A Zenoh key could not be declared or written.
    #[error("zenoh {key}: {reason}")]
    Zenoh {
        /// The key expression.
        key: String,
        /// Zenoh's message.
        reason: String,
    },
    /// A file could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A rollout's recording failed.
    #[error(transparent)]
    Recorder(#[from] scaledp_recorder::Error),
    /// The simulator failed.
    #[error(transparent)]
    Sim(#[from] scaledp_sim::Error),
    /// A thread could not be started.
    #[error("starting the {name} thread: {source}")]
    Thread {
        /// Thread name.
        name: String,
        /// The cause.
        source: std::io::Error,
    },
}

/// Result with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub(crate) fn zenoh(key: &str, e: impl std::fmt::Display) -> Self {
        Error::Zenoh {
            key: key.to_string(),
            reason: e.to_string(),
        }
    }
}
