//! The bag reader on hand-made bags: valid ones in every compression, and hostile ones
//! (truncated at every byte, lying lengths and sizes, inconsistent indexes).

use std::io::Write;
use std::path::{Path, PathBuf};

use super::read_ros1_bag;
use crate::source::{Recording, Serialization, TopicInfo};
use crate::Result;

fn field(name: &str, value: &[u8]) -> Vec<u8> {
    let mut out = ((name.len() + 1 + value.len()) as u32)
        .to_le_bytes()
        .to_vec();
    out.extend_from_slice(name.as_bytes());
    out.push(b'=');
    out.extend_from_slice(value);
    out
}

fn record(fields: &[(&str, &[u8])], data: &[u8]) -> Vec<u8> {
    let header: Vec<u8> = fields.iter().flat_map(|(n, v)| field(n, v)).collect();
    let mut out = (header.len() as u32).to_le_bytes().to_vec();
    out.extend(header);
    out.extend((data.len() as u32).to_le_bytes());
    out.extend_from_slice(data);
    out
}

fn time(ns: u64) -> Vec<u8> {
    let mut t = ((ns / 1_000_000_000) as u32).to_le_bytes().to_vec();
    t.extend(((ns % 1_000_000_000) as u32).to_le_bytes());
    t
}

const CONNS: [(&str, &str); 2] = [
    ("/cam", "sensor_msgs/Image"),
    ("/joints", "sensor_msgs/JointState"),
];

fn connection(id: u32) -> Vec<u8> {
    let (topic, ty) = CONNS[id as usize];
    let data: Vec<u8> = [
        field("topic", topic.as_bytes()),
        field("type", ty.as_bytes()),
    ]
    .concat()
    .into_iter()
    .chain(field("md5sum", b"060021388200f6f0f447d0fcd9c64743"))
    .chain(field("message_definition", b"..."))
    .collect();
    let op = [0x07];
    record(
        &[
            ("op", &op),
            ("conn", &id.to_le_bytes()),
            ("topic", topic.as_bytes()),
        ],
        &data,
    )
}

/// A bag with one chunk per entry of `chunks`, each a list of (conn, log time ns, payload).
fn make_bag(compression: &str, chunks: &[Vec<(u32, u64, Vec<u8>)>]) -> Vec<u8> {
    let mut body = Vec::new();
    let mut infos = Vec::new();
    let start = 13 + bag_header(0, 0, 0).len() as u64;
    for msgs in chunks {
        let mut data = Vec::new();
        for id in 0..CONNS.len() as u32 {
            if msgs.iter().any(|m| m.0 == id) {
                data.extend(connection(id));
            }
        }
        for (conn, t, payload) in msgs {
            data.extend(record(
                &[
                    ("op", &[0x02]),
                    ("conn", &conn.to_le_bytes()),
                    ("time", &time(*t)),
                ],
                payload,
            ));
        }
        let packed = match compression {
            "none" => data.clone(),
            "bz2" => {
                let mut e = bzip2::write::BzEncoder::new(Vec::new(), bzip2::Compression::best());
                e.write_all(&data).unwrap();
                e.finish().unwrap()
            }
            _ => {
                // Framed like roslz4 (C++ rosbag): independent blocks, 1 MiB, content checksum.
                use lz4_flex::frame::{BlockMode, BlockSize, FrameEncoder, FrameInfo};
                let info = FrameInfo::new()
                    .block_size(BlockSize::Max1MB)
                    .block_mode(BlockMode::Independent)
                    .content_checksum(true);
                let mut e = FrameEncoder::with_frame_info(info, Vec::new());
                e.write_all(&data).unwrap();
                e.finish().unwrap()
            }
        };
        let pos = start + body.len() as u64;
        let size = (data.len() as u32).to_le_bytes();
        body.extend(record(
            &[
                ("op", &[0x05]),
                ("compression", compression.as_bytes()),
                ("size", &size),
            ],
            &packed,
        ));
        let mut counts = Vec::new();
        for id in 0..CONNS.len() as u32 {
            let n = msgs.iter().filter(|m| m.0 == id).count() as u32;
            if n > 0 {
                counts.extend(id.to_le_bytes());
                counts.extend(n.to_le_bytes());
                let op = [0x04];
                let idx = [
                    ("op", &op[..]),
                    ("ver", &1u32.to_le_bytes()),
                    ("conn", &id.to_le_bytes()),
                    ("count", &n.to_le_bytes()),
                ];
                body.extend(record(&idx, &vec![0u8; 12 * n as usize]));
            }
        }
        infos.push((pos, counts));
    }
    let index_pos = start + body.len() as u64;
    for id in 0..CONNS.len() as u32 {
        body.extend(connection(id));
    }
    for (pos, counts) in &infos {
        let n = (counts.len() as u32 / 8).to_le_bytes();
        let fields = [
            ("op", &[0x06][..]),
            ("ver", &1u32.to_le_bytes()),
            ("chunk_pos", &pos.to_le_bytes()),
            ("count", &n),
        ];
        body.extend(record(&fields, counts));
    }
    let mut bag = b"#ROSBAG V2.0\n".to_vec();
    bag.extend(bag_header(
        index_pos,
        CONNS.len() as u32,
        chunks.len() as u32,
    ));
    bag.extend(body);
    bag
}

fn bag_header(index_pos: u64, conns: u32, chunks: u32) -> Vec<u8> {
    let fields = [
        ("op", &[0x03][..]),
        ("index_pos", &index_pos.to_le_bytes()),
        ("conn_count", &conns.to_le_bytes()),
        ("chunk_count", &chunks.to_le_bytes()),
    ];
    record(&fields, &[b' '; 16])
}

fn sample_chunks() -> Vec<Vec<(u32, u64, Vec<u8>)>> {
    vec![
        vec![
            (1, 1_000_000_500, vec![1, 2, 3]),
            (0, 1_000_000_300, vec![9; 40]),
            (1, 1_000_000_900, vec![]),
        ],
        vec![(1, 2_000_000_000, vec![4]), (1, 1_500_000_000, vec![5, 6])],
    ]
}

fn read(
    dir: &Path,
    name: &str,
    bytes: &[u8],
    want: &dyn Fn(&TopicInfo) -> bool,
) -> Result<Recording> {
    let path: PathBuf = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    read_ros1_bag(&path, want)
}

fn all(_: &TopicInfo) -> bool {
    true
}

#[test]
fn reads_every_compression() {
    let dir = tempfile::tempdir().unwrap();
    for compression in ["none", "bz2", "lz4"] {
        let rec = read(
            dir.path(),
            "a.bag",
            &make_bag(compression, &sample_chunks()),
            &all,
        )
        .unwrap();
        let topics: Vec<_> = rec
            .topics
            .iter()
            .map(|t| (t.topic.as_str(), t.message_type.as_str(), t.count))
            .collect();
        assert_eq!(
            topics,
            [
                ("/cam", "sensor_msgs/msg/Image", Some(1)),
                ("/joints", "sensor_msgs/msg/JointState", Some(4))
            ]
        );
        let times: Vec<u64> = rec.messages.iter().map(|m| m.log_time_ns).collect();
        assert_eq!(
            times,
            [
                1_000_000_300,
                1_000_000_500,
                1_000_000_900,
                1_500_000_000,
                2_000_000_000
            ]
        );
        assert_eq!(rec.messages[0].data, vec![9; 40]);
        assert_eq!(rec.messages[0].topic, "/cam");
        assert_eq!(rec.messages[3].data, [5, 6]);
        assert!(rec
            .messages
            .iter()
            .all(|m| m.serialization == Serialization::Ros1));
    }
}

#[test]
fn chunks_without_wanted_topics_are_not_read() {
    let dir = tempfile::tempdir().unwrap();
    let mut bag = make_bag("none", &sample_chunks());
    // Corrupt the second chunk, which only holds /joints: an op that cannot be in a chunk.
    let second = find_all(&bag, b"op=\x02").into_iter().last().unwrap();
    bag[second + 3] = 0x09;
    let cams = |t: &TopicInfo| t.topic == "/cam";
    let rec = read(dir.path(), "b.bag", &bag, &cams).unwrap();
    assert_eq!(rec.messages.len(), 1);
    let err = read(dir.path(), "b.bag", &bag, &all)
        .unwrap_err()
        .to_string();
    assert!(err.contains("unexpected record op 0x09"), "{err}");
}

fn find_all(hay: &[u8], needle: &[u8]) -> Vec<usize> {
    hay.windows(needle.len())
        .enumerate()
        .filter(|(_, w)| *w == needle)
        .map(|(i, _)| i)
        .collect()
}

#[test]
fn every_truncation_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.bag");
    for compression in ["none", "bz2", "lz4"] {
        let bag = make_bag(compression, &sample_chunks());
        std::fs::write(&path, &bag).unwrap();
        let file = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
        for cut in (0..bag.len()).rev() {
            file.set_len(cut as u64).unwrap();
            let r = read_ros1_bag(&path, &all);
            assert!(
                r.is_err(),
                "{compression} bag cut at {cut} of {} read",
                bag.len()
            );
        }
    }
}

#[test]
fn lying_lengths_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let good = make_bag("lz4", &sample_chunks());
    let check = |bytes: &[u8], expect: &str| {
        let err = read(dir.path(), "h.bag", bytes, &all)
            .unwrap_err()
            .to_string();
        assert!(err.contains(expect), "expected '{expect}' in: {err}");
        assert!(err.contains("h.bag"), "{err}");
    };
    // First record header length 4 GiB.
    let mut b = good.clone();
    b[13..17].copy_from_slice(&u32::MAX.to_le_bytes());
    check(&b, "exceeds");
    // Chunk size field claiming 4 GiB - 1 of decompressed data.
    for compression in ["none", "bz2", "lz4"] {
        let mut b = make_bag(compression, &sample_chunks());
        let at = find_all(&b, b"size=")[0] + 5;
        b[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        check(&b, "its header says 4294967295");
        // ... and claiming less than the chunk holds.
        b[at..at + 4].copy_from_slice(&10u32.to_le_bytes());
        check(&b, "its header says 10");
    }
    // Chunk info count not matching its data.
    let mut b = good.clone();
    let at = find_all(&b, b"count=").into_iter().last().unwrap() + 6;
    b[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    check(&b, "data bytes for 4294967295 connections");
    // Index position beyond the end, and an unindexed bag.
    let at = find_all(&good, b"index_pos=")[0] + 10;
    let mut b = good.clone();
    b[at..at + 8].copy_from_slice(&u64::MAX.to_le_bytes());
    check(&b, "outside the file");
    b[at..at + 8].copy_from_slice(&0u64.to_le_bytes());
    check(&b, "rosbag reindex");
    // A message count the index does not agree with.
    let mut b = make_bag("none", &sample_chunks());
    let at = find_all(&b, b"op=\x06").into_iter().last().unwrap();
    let data_start = b.len() - 8; // last chunk info: one (conn, count) pair
    assert!(data_start > at);
    b[data_start + 4..].copy_from_slice(&3u32.to_le_bytes());
    check(&b, "the index says");
}

#[test]
fn not_a_bag() {
    let dir = tempfile::tempdir().unwrap();
    let err = read(dir.path(), "x.bag", b"#ROSBAG V1.2\nxxxxxxxx", &all)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("unsupported bag version '#ROSBAG V1.2'"),
        "{err}"
    );
    let err = read(dir.path(), "x.bag", b"\x89PNG\r\n\x1a\n-------------", &all)
        .unwrap_err()
        .to_string();
    assert!(err.contains("not a ROS 1 bag"), "{err}");
    let err = read(dir.path(), "x.bag", b"", &all)
        .unwrap_err()
        .to_string();
    assert!(err.contains("truncated"), "{err}");
    assert!(read_ros1_bag(&dir.path().join("missing.bag"), &all).is_err());
}
