//! The one error type of the recorder.

use std::path::PathBuf;

/// What can go wrong while recording or recovering.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Zenoh could not be configured or opened.
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// A file could not be created, written or renamed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The MCAP writer or reader failed.
    #[error("{}: {reason}", path.display())]
    Mcap {
        /// The file.
        path: PathBuf,
        /// What the MCAP library said.
        reason: String,
    },
    /// The rig lists a topic whose message type scaledp has no definition for.
    #[error("topic {topic}: no ros2msg definition for {message_type}")]
    UnknownType {
        /// The topic.
        topic: String,
        /// Its message type.
        message_type: String,
    },
    /// The recorder's writer thread is gone.
    #[error("the recorder has stopped")]
    Stopped,
}

impl Error {
    pub(crate) fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |source| Self::Io { path, source }
    }
    /// An MCAP writer error on `path`; an I/O failure is reported with the OS's reason ("No
    /// space left on device"), which the mcap crate's own message leaves out.
    pub(crate) fn mcap(path: impl Into<PathBuf>) -> impl FnOnce(mcap::McapError) -> Self {
        let path = path.into();
        move |e| match e {
            mcap::McapError::Io(source) => Self::Io { path, source },
            e => Self::Mcap {
                path,
                reason: chain(&e),
            },
        }
    }
}

/// An error's message followed by those of its sources, each once.
pub(crate) fn chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        let m = s.to_string();
        if !text.contains(&m) {
            text.push_str(": ");
            text.push_str(&m);
        }
        source = s.source();
    }
    text
}

/// Result with this crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
