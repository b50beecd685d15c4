//! ROS 1 bag records in memory: `name=value` header fields, connection and chunk info records,
//! and the records inside a decompressed chunk. Every length is checked against what remains.

use std::collections::BTreeMap;

use crate::source::ros2_type_name;

/// Message data (inside chunks).
pub const OP_MSG_DATA: u8 = 0x02;
/// The bag header (first record).
pub const OP_BAG_HEADER: u8 = 0x03;
/// A chunk of message data and connection records. (Index data records, op 0x04, follow each
/// chunk and repeat what the chunk infos say; they are never read: chunks are found by position.)
pub const OP_CHUNK: u8 = 0x05;
/// Chunk info (index section).
pub const OP_CHUNK_INFO: u8 = 0x06;
/// Connection (inside chunks and in the index section).
pub const OP_CONNECTION: u8 = 0x07;

type Res<T> = std::result::Result<T, String>;

/// A connection: topic (with its leading `/`) and type (ROS 2 form).
pub struct Connection {
    pub topic: String,
    pub message_type: String,
}

/// A chunk info record: where the chunk is and how many messages of each connection it holds.
pub struct ChunkInfo {
    /// Offset of the chunk info record itself (for errors).
    pub at: u64,
    pub chunk_pos: u64,
    /// Messages per connection (no zero entries).
    pub counts: BTreeMap<u32, u32>,
}

/// A `u32` length and that many bytes from `data` at `*pos`, checked against what remains.
pub fn take_block<'a>(data: &'a [u8], pos: &mut usize, what: &str) -> Res<&'a [u8]> {
    let rest = data.get(*pos..).unwrap_or_default();
    let Some((len, rest)) = rest.split_first_chunk::<4>() else {
        return Err(format!(
            "ends inside the {what} length ({} bytes left)",
            rest.len()
        ));
    };
    let n = u32::from_le_bytes(*len) as usize;
    if n > rest.len() {
        return Err(format!(
            "{what} length {n} exceeds the {} bytes left",
            rest.len()
        ));
    }
    *pos += 4 + n;
    Ok(&rest[..n])
}

/// The `name=value` fields of a record header (or of connection data).
pub struct Fields<'a>(Vec<(&'a str, &'a [u8])>);

impl<'a> Fields<'a> {
    /// Splits `buf` into its length-prefixed fields.
    pub fn parse(buf: &'a [u8]) -> Res<Self> {
        let (mut fields, mut pos) = (Vec::new(), 0);
        while pos < buf.len() {
            let field = take_block(buf, &mut pos, "header field")?;
            let eq = field
                .iter()
                .position(|&b| b == b'=')
                .ok_or("header field without '='")?;
            let name = std::str::from_utf8(&field[..eq]).map_err(|_| "field name is not UTF-8")?;
            fields.push((name, &field[eq + 1..]));
        }
        Ok(Self(fields))
    }

    fn get(&self, name: &str) -> Res<&'a [u8]> {
        let found = self.0.iter().find(|(n, _)| *n == name).map(|(_, v)| *v);
        found.ok_or_else(|| format!("header has no '{name}' field"))
    }

    fn fixed<const N: usize>(&self, name: &str) -> Res<[u8; N]> {
        let v = self.get(name)?;
        v.try_into()
            .map_err(|_| format!("field '{name}' has {} bytes, expected {N}", v.len()))
    }

    /// The record's op code.
    pub fn op(&self) -> Res<u8> {
        Ok(self.fixed::<1>("op")?[0])
    }

    /// A little-endian `u32` field.
    pub fn u32(&self, name: &str) -> Res<u32> {
        Ok(u32::from_le_bytes(self.fixed(name)?))
    }

    /// A little-endian `u64` field.
    pub fn u64(&self, name: &str) -> Res<u64> {
        Ok(u64::from_le_bytes(self.fixed(name)?))
    }

    /// A ROS time field (`u32` sec, `u32` nsec) as ns since the epoch (cannot overflow `u64`).
    pub fn time(&self, name: &str) -> Res<u64> {
        let [s0, s1, s2, s3, n0, n1, n2, n3] = self.fixed::<8>(name)?;
        let sec = u32::from_le_bytes([s0, s1, s2, s3]);
        Ok(u64::from(sec) * 1_000_000_000 + u64::from(u32::from_le_bytes([n0, n1, n2, n3])))
    }

    /// A UTF-8 string field.
    pub fn string(&self, name: &str) -> Res<String> {
        let v = self.get(name)?.to_vec();
        String::from_utf8(v).map_err(|_| format!("field '{name}' is not UTF-8"))
    }
}

/// A connection record: header `conn`, `topic`; data = fields `type`, `md5sum`,
/// `message_definition`, … (only `type` is used).
pub fn connection(header: &Fields<'_>, data: &[u8]) -> Res<(u32, Connection)> {
    let id = header.u32("conn")?;
    let mut topic = header.string("topic")?;
    let ty = Fields::parse(data)
        .and_then(|d| d.string("type"))
        .map_err(|e| format!("connection {id} data: {e}"))?;
    if !topic.starts_with('/') {
        topic.insert(0, '/');
    }
    Ok((
        id,
        Connection {
            topic,
            message_type: ros2_type_name(&ty),
        },
    ))
}

/// A chunk info record (version 1): `chunk_pos`, and `count` pairs of (conn, messages) as data.
pub fn chunk_info(at: u64, header: &Fields<'_>, data: &[u8]) -> Res<ChunkInfo> {
    let ver = header.u32("ver")?;
    if ver != 1 {
        return Err(format!("chunk info version {ver}, expected 1"));
    }
    let chunk_pos = header.u64("chunk_pos")?;
    let count = header.u32("count")?;
    if data.len() as u64 != u64::from(count) * 8 {
        return Err(format!(
            "chunk info has {} data bytes for {count} connections",
            data.len()
        ));
    }
    let mut counts = BTreeMap::new();
    for pair in data.chunks_exact(8) {
        let [c0, c1, c2, c3, n0, n1, n2, n3] = pair.try_into().map_err(|_| "short entry")?;
        let n = u32::from_le_bytes([n0, n1, n2, n3]);
        if n > 0 {
            let conn = u32::from_le_bytes([c0, c1, c2, c3]);
            let total: &mut u32 = counts.entry(conn).or_default();
            *total = total.checked_add(n).ok_or("chunk info count overflows")?;
        }
    }
    Ok(ChunkInfo {
        at,
        chunk_pos,
        counts,
    })
}

/// Walks the records of a decompressed chunk: connection records are skipped (the index has
/// them); each message data record goes to `on_message(conn, log_time_ns, payload)`. Errors name
/// the byte of the chunk where the bad record starts.
pub fn parse_chunk(data: &[u8], mut on_message: impl FnMut(u32, u64, &[u8]) -> Res<()>) -> Res<()> {
    let mut pos = 0usize;
    while pos < data.len() {
        let at = pos;
        let step = next_record(data, &mut pos).and_then(|(fields, payload)| match fields.op()? {
            OP_CONNECTION => Ok(()),
            OP_MSG_DATA => on_message(fields.u32("conn")?, fields.time("time")?, payload),
            op => Err(format!("unexpected record op {op:#04x} inside a chunk")),
        });
        step.map_err(|e| format!("chunk byte {at}: {e}"))?;
    }
    Ok(())
}

/// The header fields and data of the record at `*pos`.
fn next_record<'a>(data: &'a [u8], pos: &mut usize) -> Res<(Fields<'a>, &'a [u8])> {
    let header = take_block(data, pos, "record header")?;
    let payload = take_block(data, pos, "record data")?;
    Ok((Fields::parse(header)?, payload))
}
