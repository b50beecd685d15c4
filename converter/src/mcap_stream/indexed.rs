//! Chunks picked from an MCAP file's chunk index and fetched by range, read with the schemas and
//! channels its summary lists (a chunk may use a channel defined in an earlier one): how the
//! second read of a recording in object storage fetches only the chunks that hold the frames
//! it still needs. Each chunk goes through the same checks (sizes, CRC) as in a linear read.

use std::collections::BTreeMap;
use std::path::Path;

use mcap::records::op;

use super::reader::{record_at, Buffers, Metadata, OnMessage, Reader};
use crate::error::{Error, Result};
use crate::source::TopicInfo;

/// Reads the chunk records `chunks` (each a whole record: opcode, length, body) of `path`,
/// calling `on_message` for their messages until it returns false.
pub(crate) fn stream_chunks(
    path: &Path,
    schemas: BTreeMap<u16, String>,
    channels: BTreeMap<u16, TopicInfo>,
    chunks: &mut dyn Iterator<Item = Result<bytes::Bytes>>,
    on_message: &mut OnMessage<'_>,
) -> Result<()> {
    let mut reader = Reader {
        path,
        schemas,
        channels,
        metadata: Metadata::new(),
        first: false,
        buffers: Buffers::default(),
    };
    for chunk in chunks {
        let chunk = chunk?;
        let bad = |what: &str| Error::input(path, format!("corrupt MCAP chunk index: {what}"));
        let (opcode, end) = record_at(&chunk, 0, chunk.len())
            .ok_or_else(|| bad("an indexed range holds no whole record"))?;
        if opcode != op::CHUNK {
            return Err(bad("an indexed range is not a chunk"));
        }
        let body = chunk.get(9..end).unwrap_or_default();
        if !reader.record(op::CHUNK, body, None, on_message)? {
            break;
        }
    }
    Ok(())
}
