//! Tests of [`super`]: round trips and hostile files.

#![allow(clippy::unwrap_used)]
use super::reader::*;
use super::*;
use mcap::records::op;
use std::collections::BTreeMap;

/// (topic, log time, payload) of the messages written: every third a small one, the others
/// large "frames", so that most 3 MiB chunks end with a frame.
fn messages() -> Messages {
    (0..12u64)
        .map(|i| {
            let (topic, len) = match i % 3 {
                0 => ("/arm", 100 + i as usize),
                _ => ("/cam", (1 << 20) + 12_345 * i as usize),
            };
            // Compressible, but different per message.
            let data = (0..len)
                .map(|k| ((k / 7) as u64 ^ i.wrapping_mul(31)) as u8)
                .collect();
            (topic.to_string(), 1_000 + i, data)
        })
        .collect()
}

fn file_of(compression: Option<mcap::Compression>) -> (tempfile::NamedTempFile, Messages) {
    let sent = messages();
    let mut f = tempfile::NamedTempFile::new().unwrap();
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .compression(compression)
        .chunk_size(Some(3 << 20))
        .create(std::io::BufWriter::new(f.as_file_mut()))
        .unwrap();
    let image = w
        .add_schema("sensor_msgs/msg/Image", "ros2msg", b"")
        .unwrap();
    let joints = w
        .add_schema("sensor_msgs/msg/JointState", "ros2msg", b"")
        .unwrap();
    let cam = w
        .add_channel(image, "/cam", "cdr", &BTreeMap::new())
        .unwrap();
    let arm = w
        .add_channel(joints, "/arm", "cdr", &BTreeMap::new())
        .unwrap();
    for (i, (topic, log, data)) in sent.iter().enumerate() {
        let header = mcap::records::MessageHeader {
            channel_id: if topic == "/cam" { cam } else { arm },
            sequence: i as u32,
            log_time: *log,
            publish_time: *log,
        };
        w.write_to_known_channel(&header, data).unwrap();
    }
    w.finish().unwrap();
    drop(w);
    (f, sent)
}

/// (topic, log time, payload) per message.
type Messages = Vec<(String, u64, Vec<u8>)>;

/// The messages of `path` and how many were left compressed.
fn read_all(path: &Path) -> Result<(Messages, usize)> {
    let mut got = Vec::new();
    let mut deferred = 0;
    stream(path, &mut |t, log, payload, _| {
        deferred += usize::from(matches!(payload, Payload::Deferred(_)));
        let prefix = payload.prefix().to_vec();
        let data = payload
            .share()
            .with(<[u8]>::to_vec)
            .map_err(|e| Error::input(path, format!("corrupt MCAP chunk: {e}")))?;
        assert!(data.starts_with(&prefix));
        got.push((t.topic.clone(), log, data));
        Ok(true)
    })?;
    Ok((got, deferred))
}

#[test]
fn every_compression_reads_back_what_was_written() {
    for c in [
        None,
        Some(mcap::Compression::Lz4),
        Some(mcap::Compression::Zstd),
    ] {
        let (f, sent) = file_of(c);
        let (got, deferred) = read_all(f.path()).unwrap();
        assert_eq!(got, sent, "{c:?}");
        // Only LZ4 chunks leave their large last message compressed.
        assert_eq!(
            deferred > 0,
            matches!(c, Some(mcap::Compression::Lz4)),
            "{c:?}"
        );
    }
}

#[test]
fn the_hash_taken_on_the_way_is_the_content_hash() {
    let (f, _) = file_of(Some(mcap::Compression::Lz4));
    let mut h = blake3::Hasher::new();
    h.update(f.path().file_name().unwrap().as_encoded_bytes());
    stream_hashed(f.path(), Some(&mut h), &mut |_, _, _, _| Ok(true)).unwrap();
    let on_the_way = h.finalize().to_hex().to_string();
    assert_eq!(on_the_way, crate::content_hash(f.path()).unwrap());
}

#[test]
fn truncated_and_corrupt_files_are_errors() {
    let (f, _) = file_of(Some(mcap::Compression::Lz4));
    let bytes = std::fs::read(f.path()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let e = read_all(&cut).unwrap_err().to_string();
    assert!(e.contains("cut.mcap") && e.contains("recover"), "{e}");
    // Flip bytes inside the compressed data of the first chunk (well past its header).
    let mut bad = bytes.clone();
    let at = bytes
        .windows(4)
        .position(|w| w == [0x04, 0x22, 0x4D, 0x18])
        .unwrap();
    for b in &mut bad[at + 200..at + 260] {
        *b ^= 0x5A;
    }
    let bad_path = dir.path().join("bad.mcap");
    std::fs::write(&bad_path, &bad).unwrap();
    match read_all(&bad_path) {
        Err(e) => assert!(e.to_string().contains("bad.mcap"), "{e}"),
        // A flip that still decodes yields other bytes, never a panic.
        Ok((got, _)) => assert_eq!(got.len(), 12),
    }
}

/// Offsets of the file-level chunk records of an MCAP file.
fn chunks(bytes: &[u8]) -> Vec<usize> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + 9 <= bytes.len() - 8 {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        if bytes[at] == op::CHUNK {
            out.push(at);
        }
        at += 9 + len;
    }
    out
}

/// Writes `bytes` as `name` in `dir`; returns the path.
fn put(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

#[test]
fn a_garbage_record_length_is_an_error_not_an_allocation() {
    let (f, _) = file_of(Some(mcap::Compression::Lz4));
    let bytes = std::fs::read(f.path()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let at = chunks(&bytes)[1];
    // Terabytes; past the end of the file; next to u64::MAX (overflows an unchecked `9 + len`).
    let lens = [1u64 << 40, bytes.len() as u64, u64::MAX - 4];
    for (k, len) in lens.into_iter().enumerate() {
        let mut bad = bytes.clone();
        bad[at + 1..at + 9].copy_from_slice(&len.to_le_bytes());
        let path = put(&dir, &format!("len{k}.mcap"), &bad);
        let e = read_all(&path).unwrap_err().to_string();
        assert!(
            e.contains(&format!("len{k}.mcap")) && e.contains("truncated or corrupt MCAP"),
            "{e}"
        );
    }
}

/// A record: opcode, length, body.
fn rec(opcode: u8, body: &[u8]) -> Vec<u8> {
    let mut r = vec![opcode];
    r.extend_from_slice(&(body.len() as u64).to_le_bytes());
    r.extend_from_slice(body);
    r
}

fn string(s: &str) -> Vec<u8> {
    let mut r = (s.len() as u32).to_le_bytes().to_vec();
    r.extend_from_slice(s.as_bytes());
    r
}

/// A chunk record holding `data` (`size` bytes of records once decompressed).
fn chunk_rec(compression: &str, size: usize, crc: u32, data: &[u8]) -> Vec<u8> {
    let mut body = [0u64, 0, size as u64].map(u64::to_le_bytes).concat();
    body.extend_from_slice(&crc.to_le_bytes());
    body.extend(string(compression));
    body.extend_from_slice(&(data.len() as u64).to_le_bytes());
    body.extend_from_slice(data);
    rec(op::CHUNK, &body)
}

/// A ros2 MCAP file: magic, header, an image schema and channel 1 ("/cam"), `records`, data
/// end, footer, magic.
fn mcap_of(records: &[u8]) -> Vec<u8> {
    let mut f = mcap::MAGIC.to_vec();
    f.extend(rec(op::HEADER, &[string("ros2"), string("test")].concat()));
    let schema = [
        1u16.to_le_bytes().to_vec(),
        string("sensor_msgs/msg/Image"),
        string("ros2msg"),
        0u32.to_le_bytes().to_vec(),
    ];
    f.extend(rec(op::SCHEMA, &schema.concat()));
    let channel = [
        1u16.to_le_bytes().to_vec(),
        1u16.to_le_bytes().to_vec(),
        string("/cam"),
        string("cdr"),
        0u32.to_le_bytes().to_vec(),
    ];
    f.extend(rec(op::CHANNEL, &channel.concat()));
    f.extend_from_slice(records);
    f.extend(rec(op::DATA_END, &0u32.to_le_bytes()));
    f.extend(rec(op::FOOTER, &[0u8; 20]));
    f.extend_from_slice(mcap::MAGIC);
    f
}

#[test]
fn a_chunk_inside_a_chunk_is_an_error() {
    // 20 000 chunks each inside the previous: recursing into them would overflow the stack.
    let depth = 20_000;
    let header = chunk_rec("", 0, 0, &[]).len();
    let mut nested = Vec::with_capacity(depth * header);
    for d in 1..=depth {
        // Only the chunk's header: its records (the next chunk) follow.
        let inner = (depth - d) * header;
        let mut head = chunk_rec("", inner, 0, &[]);
        head[1..9].copy_from_slice(&((header - 9 + inner) as u64).to_le_bytes());
        head[header - 8..].copy_from_slice(&(inner as u64).to_le_bytes());
        nested.extend(head);
    }
    let dir = tempfile::tempdir().unwrap();
    let path = put(&dir, "nested.mcap", &mcap_of(&nested));
    let e = read_all(&path).unwrap_err().to_string();
    assert!(
        e.contains("nested.mcap") && e.contains("chunk record inside a chunk"),
        "{e}"
    );
}

#[test]
fn a_chunk_whose_records_do_not_match_its_crc_is_an_error() {
    for c in [
        None,
        Some(mcap::Compression::Lz4),
        Some(mcap::Compression::Zstd),
    ] {
        let (f, sent) = file_of(c);
        let bytes = std::fs::read(f.path()).unwrap();
        let dir = tempfile::tempdir().unwrap();
        // Each chunk in turn with a CRC off by one bit: the records decode fine, the check
        // fails (for an LZ4 chunk ending with a large message, when that message is decoded).
        let all = chunks(&bytes);
        assert!(all.len() > 2, "{c:?}");
        for (k, at) in all.into_iter().enumerate() {
            let mut bad = bytes.clone();
            assert_ne!(bad[at + 33..at + 37], [0; 4], "the writer records CRCs");
            bad[at + 33] ^= 1;
            let name = format!("crc{k}.mcap");
            let e = read_all(&put(&dir, &name, &bad)).unwrap_err().to_string();
            assert!(
                e.contains(&name) && e.contains("CRC-32 of its records"),
                "{c:?}: {e}"
            );
        }
        let (got, _) = read_all(&put(&dir, "good.mcap", &bytes)).unwrap();
        assert_eq!(got, sent);
    }
}

/// LZ4 frame of `bytes` in blocks of 64 KiB.
fn lz4_of(bytes: &[u8]) -> Vec<u8> {
    use lz4_flex::frame::{BlockSize, FrameEncoder, FrameInfo};
    let info = FrameInfo::new().block_size(BlockSize::Max64KB);
    let mut enc = FrameEncoder::with_frame_info(info, Vec::new());
    std::io::Write::write_all(&mut enc, bytes).unwrap();
    enc.finish().unwrap()
}

#[test]
fn an_lz4_chunk_cut_before_its_large_last_message_is_an_error() {
    // Two messages on "/cam": one ending 20 bytes before 64 KiB (noise, so that the chunk's
    // compressed size is plausible for its records), one of 2 MiB after it (left compressed
    // when whole).
    let message = |data: &[u8]| {
        let mut body = [1u16.to_le_bytes().to_vec(), 0u32.to_le_bytes().to_vec()].concat();
        body.extend_from_slice(&[7u64, 7].map(u64::to_le_bytes).concat());
        body.extend_from_slice(data);
        rec(op::MESSAGE, &body)
    };
    let mut x = 1u32;
    let noise: Vec<u8> = (0..(64 << 10) - 20 - 31)
        .map(|_| {
            x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (x >> 24) as u8
        })
        .collect();
    let mut records = message(&noise);
    assert_eq!(records.len(), (64 << 10) - 20);
    records.extend(message(&[2; 2 << 20]));
    let dir = tempfile::tempdir().unwrap();
    // The LZ4 data holds the first 64 KiB only, ending cleanly after that block.
    let cut = chunk_rec("lz4", records.len(), 0, &lz4_of(&records[..64 << 10]));
    let path = put(&dir, "cut.mcap", &mcap_of(&cut));
    // Even a reader that never decodes the last message sees the error.
    let e = stream(&path, &mut |_, _, _, _| Ok(true))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("cut.mcap") && e.contains("its header says"),
        "{e}"
    );
    // The same chunk whole reads back, its last message left compressed.
    let crc = crc32fast::hash(&records);
    let whole = chunk_rec("lz4", records.len(), crc, &lz4_of(&records));
    let (got, deferred) = read_all(&put(&dir, "whole.mcap", &mcap_of(&whole))).unwrap();
    assert_eq!((got.len(), deferred), (2, 1));
    assert_eq!(got[1].2, vec![2; 2 << 20]);
}
