//! The one error type of the converter. Every variant names the file it is about, so a batch
//! can report "one clear line naming the file and the reason" per failed episode.

use std::path::PathBuf;

/// What can go wrong converting one input.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A recording or bag is malformed or unsupported (truncated, wrong profile, bad record…).
    #[error("{}: {reason}", path.display())]
    Input {
        /// The file.
        path: PathBuf,
        /// What is wrong, in one line.
        reason: String,
    },
    /// One message could not be decoded.
    #[error("{}: {topic} message at {log_time_ns} ns: {reason}", path.display())]
    Message {
        /// The file.
        path: PathBuf,
        /// Its topic.
        topic: String,
        /// Its log time.
        log_time_ns: u64,
        /// What is wrong.
        reason: String,
    },
    /// The episode cannot become training data (missing camera, too many stale ticks…).
    #[error("{}: rejected: {reason}", path.display())]
    Rejected {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// The job has unlabelled inputs and was not told whether to keep or skip them
    /// ([`crate::Unlabeled::Refuse`]); nothing was converted. The message lists them.
    #[error("{line}")]
    Unlabeled {
        /// The unlabelled inputs.
        inputs: Vec<PathBuf>,
        /// The refusal in one line.
        line: String,
    },
    /// Object storage failed (no such bucket, refused credentials, access denied, the network
    /// after the retries); the message names the URL.
    #[error(transparent)]
    Store(#[from] scaledp_store::Error),
    /// The output dataset could not be written or read back.
    #[error("{}: {reason}", path.display())]
    Dataset {
        /// The dataset directory or file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

impl Error {
    /// An [`Error::Input`] for `path`.
    pub fn input(path: impl Into<PathBuf>, reason: impl std::fmt::Display) -> Self {
        Self::Input {
            path: path.into(),
            reason: reason.to_string(),
        }
    }
    /// The error on one line, as a report of failed inputs shows it (a library's message may
    /// end in a newline or span several).
    pub fn one_line(&self) -> String {
        self.to_string()
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ")
    }
    /// The same error about `to` instead of `from` (or a file under it): a downloaded copy's
    /// errors name the object it came from.
    pub(crate) fn renamed(self, from: &std::path::Path, to: &std::path::Path) -> Self {
        let swap = |p: PathBuf| match p.strip_prefix(from) {
            Ok(rel) if rel.as_os_str().is_empty() => to.to_path_buf(),
            Ok(rel) => to.join(rel),
            Err(_) => p,
        };
        match self {
            Self::Io { path, source } => Self::Io {
                path: swap(path),
                source,
            },
            Self::Input { path, reason } => Self::Input {
                path: swap(path),
                reason,
            },
            Self::Message {
                path,
                topic,
                log_time_ns,
                reason,
            } => Self::Message {
                path: swap(path),
                topic,
                log_time_ns,
                reason,
            },
            Self::Rejected { path, reason } => Self::Rejected {
                path: swap(path),
                reason,
            },
            Self::Dataset { path, reason } => Self::Dataset {
                path: swap(path),
                reason,
            },
            other => other,
        }
    }
    /// A closure turning an I/O error on `path` into an [`Error::Io`].
    pub fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |source| Self::Io { path, source }
    }
}

/// Result with this crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
