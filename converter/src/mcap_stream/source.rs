//! The front-to-back read of an MCAP file from any byte source (a local file, or an object
//! read through ranged GETs): the magic checked, every byte optionally hashed, records handed to
//! [`super::Reader`] as the sans-io linear reader finds them.

use std::collections::BTreeMap;
use std::io::{BufReader, Read};
use std::path::Path;

use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use super::reader::{Buffers, Metadata, OnMessage, Reader, MAX_CHUNK};
use crate::error::{Error, Result};
use crate::source::TopicInfo;

/// Reads the first bytes of `src` (of `len` bytes) and refuses anything that does not start
/// with the MCAP magic (empty, or another format named `.mcap`); returns them.
fn check_magic(path: &Path, src: &mut impl Read, len: u64) -> Result<Vec<u8>> {
    let mut magic = vec![0u8; len.min(8) as usize];
    src.read_exact(&mut magic).map_err(Error::io(path))?;
    if magic[..] != mcap::MAGIC[..magic.len()] {
        return Err(Error::input(path, "not an MCAP file (no MCAP magic)"));
    }
    if magic.len() < 8 {
        return Err(Error::input(
            path,
            format!("not an MCAP file: {len} bytes, shorter than the magic"),
        ));
    }
    Ok(magic)
}

/// A read that also feeds a hasher.
struct Hashing<'h, R> {
    src: R,
    hasher: Option<&'h mut blake3::Hasher>,
}

impl<R: Read> Read for Hashing<'_, R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.src.read(buf)?;
        if let Some(h) = &mut self.hasher {
            h.update(&buf[..n]);
        }
        Ok(n)
    }
}

/// Streams the MCAP bytes of `src` (`len` bytes, named `path` in errors) like
/// [`super::stream`], feeding every byte to `hasher` on the way.
pub(crate) fn stream_from(
    path: &Path,
    mut src: impl Read,
    len: u64,
    hasher: Option<&mut blake3::Hasher>,
    on_message: &mut OnMessage<'_>,
) -> Result<(Vec<TopicInfo>, Metadata)> {
    let magic = check_magic(path, &mut src, len)?;
    let hashing = hasher.is_some();
    let src = std::io::Cursor::new(magic).chain(src);
    let mut src = BufReader::with_capacity(1 << 20, Hashing { src, hasher });
    // No record is longer than the file, nor than the largest chunk we accept compressed (LZ4
    // and zstd grow incompressible data by well under 1/64): a corrupt length is refused before
    // anything is allocated for it.
    let limit = usize::try_from(len)
        .unwrap_or(usize::MAX)
        .min(MAX_CHUNK + MAX_CHUNK / 64);
    let mut linear = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_emit_chunks(true)
            .with_record_length_limit(limit),
    );
    let mut reader = Reader {
        path,
        schemas: BTreeMap::new(),
        channels: BTreeMap::new(),
        metadata: Metadata::new(),
        first: true,
        buffers: Buffers::default(),
    };
    while let Some(event) = linear.next_event() {
        match event.map_err(|e| {
            Error::input(
                path,
                format!("truncated or corrupt MCAP ({e}); try `scaledp recover`"),
            )
        })? {
            LinearReadEvent::ReadRequest(n) => {
                let got = src.read(linear.insert(n)).map_err(Error::io(path))?;
                linear.notify_read(got);
            }
            LinearReadEvent::Record { data, opcode } => {
                if !reader.record(opcode, data, None, on_message)? {
                    return Ok((Vec::new(), reader.metadata));
                }
            }
        }
    }
    if hashing {
        // Whatever follows the end magic counts too.
        std::io::copy(&mut src, &mut std::io::sink()).map_err(Error::io(path))?;
    }
    let mut topics: Vec<TopicInfo> = reader.channels.into_values().collect();
    topics.sort_by(|a, b| a.topic.cmp(&b.topic));
    topics.dedup_by(|a, b| a.topic == b.topic);
    Ok((topics, reader.metadata))
}
