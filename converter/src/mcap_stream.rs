//! Streams a ros2-profile MCAP file message by message in one forward read. Each chunk is
//! decompressed into a recycled buffer (LZ4 with [`crate::lz4`], so no XXH32 checksum is
//! computed; zstd; or none), its records checked against the chunk's CRC-32 (see [`crate::lz4`]
//! for the one exception), and messages are handed out borrowed from it, so a camera frame is
//! never copied: a caller that keeps one (to encode it on another thread) keeps a
//! reference-counted handle on the chunk instead.
//!
//! A chunk closes after the message that takes it past its size, so in camera recordings most
//! chunks end with a frame, and most frames are never used (30 Hz cameras, 10 Hz output). An LZ4
//! chunk's last message, when large, is therefore left compressed: callers see its first bytes
//! (enough for its header stamp) and decode the rest only if they keep it ([`FrameBytes`]).
//!
//! Memory: the chunks whose frames are still referenced, each the chunk's uncompressed size (our
//! recorder writes ~8–12 MB chunks), plus ~0.3 MB per frame left compressed.

use std::fs::File;
use std::path::Path;

use crate::error::{Error, Result};
use crate::source::TopicInfo;

mod indexed;
mod reader;
mod source;

pub(crate) use indexed::stream_chunks;
pub use reader::{FrameBytes, Metadata, OnMessage, Payload};
pub(crate) use source::stream_from;

/// Streams `path`, calling `on_message` for each message until it returns false; returns the
/// topics (sorted, deduplicated; none when stopped early) and metadata records. Checks the `ros2` profile, `cdr` encodings
/// of image channels and the end of the file.
pub fn stream(path: &Path, on_message: &mut OnMessage<'_>) -> Result<(Vec<TopicInfo>, Metadata)> {
    stream_hashed(path, None, on_message)
}

/// [`stream`], feeding every byte of the file to `hasher` on the way (for a content hash
/// without a second read of the file).
pub fn stream_hashed(
    path: &Path,
    hasher: Option<&mut blake3::Hasher>,
    on_message: &mut OnMessage<'_>,
) -> Result<(Vec<TopicInfo>, Metadata)> {
    let file = File::open(path).map_err(Error::io(path))?;
    let len = file.metadata().map_err(Error::io(path))?.len();
    stream_from(path, file, len, hasher, on_message)
}

#[cfg(test)]
mod tests;
