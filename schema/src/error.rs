//! The one error type of this crate.

use std::path::PathBuf;

/// What went wrong in decoding a message or reading a rig description.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A CDR payload is malformed; `offset` counts from the start of the payload.
    #[error("bad CDR at byte {offset}: {reason}")]
    Cdr {
        /// Byte offset in the payload, encapsulation header included.
        offset: usize,
        /// What is wrong.
        reason: String,
    },
    /// A rig description could not be read or is inconsistent.
    #[error("{}: {reason}", path.display())]
    Rig {
        /// The rig file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A topic remapping (`FROM:=TO`) does not fit the rig.
    #[error("remap {from}:={to}: {reason}")]
    Remap {
        /// The rig's topic.
        from: String,
        /// Its new name.
        to: String,
        /// What is wrong.
        reason: String,
    },
    /// A kinematic computation got input it cannot use.
    #[error("kinematics: {0}")]
    Kinematics(String),
}

/// Result with this crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
