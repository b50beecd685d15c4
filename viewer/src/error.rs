//! The one error type of the viewer: every message names the input, file or address it is
//! about and what is wrong, in one line.

use std::path::PathBuf;

/// What can go wrong showing something in rerun.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A path that is none of the inputs the viewer reads.
    #[error("{}: {reason}", path.display())]
    UnknownInput {
        /// The path given.
        path: PathBuf,
        /// Why it is not an input (and what would be).
        reason: String,
    },
    /// An episode index the input does not have.
    #[error("{location}: no episode {episode} ({available})")]
    NoSuchEpisode {
        /// The dataset or directory.
        location: String,
        /// The index asked for.
        episode: u64,
        /// Which episodes there are, e.g. `episodes 0..=4`.
        available: String,
    },
    /// A recording or bag could not be read.
    #[error(transparent)]
    Converter(#[from] scaledp_converter::Error),
    /// A dataset could not be read.
    #[error(transparent)]
    Dataset(#[from] scaledp_datasets::Error),
    /// A file of the input is malformed.
    #[error("{location}: {reason}")]
    Input {
        /// The file (path or URL).
        location: String,
        /// What is wrong.
        reason: String,
    },
    /// No viewer listens at the address given.
    #[error("cannot reach a rerun viewer at {url}: {reason}")]
    Unreachable {
        /// The address.
        url: String,
        /// Why.
        reason: String,
    },
    /// No `rerun` binary to spawn.
    #[error("no rerun viewer found on PATH: install one with `pip install rerun-sdk==0.36.3`, or write a file with --save out.rrd")]
    NoViewer,
    /// The rerun SDK failed (opening a sink, logging, flushing).
    #[error("rerun: {0}")]
    Rerun(String),
    /// Writing the output failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

impl Error {
    /// An [`Error::Input`] for `location`.
    pub(crate) fn input(location: impl std::fmt::Display, reason: impl std::fmt::Display) -> Self {
        Self::Input {
            location: location.to_string(),
            reason: reason.to_string(),
        }
    }

    /// A closure turning an I/O error on `path` into an [`Error::Io`].
    pub(crate) fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |source| Self::Io { path, source }
    }

    /// An [`Error::Rerun`] from any SDK error.
    pub(crate) fn rerun(e: impl std::fmt::Display) -> Self {
        Self::Rerun(e.to_string())
    }
}

/// Result with this crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
