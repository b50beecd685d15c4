//! The crate's error type: every message names the file (or key) and what is wrong with it.

use std::path::PathBuf;

/// What went wrong opening or reading a dataset.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Object storage refused or failed a request.
    #[error("{path}: {reason}")]
    Store {
        /// The object (`s3://bucket/key`).
        path: String,
        /// Why.
        reason: String,
    },
    /// A file of the dataset is not what LeRobot v3.0 writes.
    #[error("{path}: {reason}")]
    Format {
        /// The file (relative to the dataset root).
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// The options do not fit the dataset.
    #[error("{0}")]
    Options(String),
    /// A camera frame (an image in a data file, a frame of a video file) could not be found or
    /// decoded.
    #[error("{path}: episode {episode} frame {frame} camera {camera}: {reason}")]
    Image {
        /// The data or video file.
        path: String,
        /// Episode index.
        episode: i64,
        /// Frame index in the episode.
        frame: usize,
        /// Camera key.
        camera: String,
        /// Why.
        reason: String,
    },
    /// The loader's background thread is gone (it panicked or was stopped).
    #[error("the loader's prefetch thread stopped: {0}")]
    Stopped(String),
}

/// `Result` with this crate's [`Error`].
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    pub(crate) fn format(path: impl Into<String>, reason: impl std::fmt::Display) -> Self {
        Error::Format {
            path: path.into(),
            reason: reason.to_string(),
        }
    }
}
