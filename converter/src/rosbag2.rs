//! rosbag2 input: a bag directory with mcap or sqlite3 (`.db3`) storage files, or a standalone
//! `.db3` file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rusqlite::{Connection, OpenFlags};

use crate::error::{Error, Result};
use crate::mcap_source::read_mcap;
use crate::source::{ros2_type_name, RawMessage, Recording, Serialization, TopicInfo};

/// Reads a rosbag2: either a bag directory (it has a `metadata.yaml` and one or more `.mcap` or
/// `.db3` storage files, read in file-name order and merged) or a standalone `.db3` (or `.mcap`)
/// file. Returns its topics (counts summed over the storage files), the messages of the topics
/// `want` accepts sorted by log time, and the metadata records of mcap storage.
///
/// `metadata.yaml` only marks the directory as a bag; its content is not read (the storage
/// files say everything needed). For split bags `want` sees each file's topics with that file's
/// counts. Compressed storage files (`.mcap.zstd`, `.db3.zstd`) are rejected with a hint.
/// sqlite3 topics must be `cdr`-serialized.
pub fn read_rosbag2(path: &Path, want: &dyn Fn(&TopicInfo) -> bool) -> Result<Recording> {
    let meta = std::fs::metadata(path).map_err(Error::io(path))?;
    if !meta.is_dir() {
        return read_storage(path, want);
    }
    if !path.join("metadata.yaml").is_file() {
        return Err(Error::input(
            path,
            "not a rosbag2 directory (no metadata.yaml)",
        ));
    }
    let mut files: Vec<PathBuf> = Vec::new();
    for entry in std::fs::read_dir(path).map_err(Error::io(path))? {
        let p = entry.map_err(Error::io(path))?.path();
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if name.ends_with(".mcap.zstd") || name.ends_with(".db3.zstd") {
            return Err(Error::input(
                &p,
                "compressed rosbag2 storage is not supported; decompress it first (`ros2 bag convert`)",
            ));
        }
        if p.is_file() && (name.ends_with(".mcap") || name.ends_with(".db3")) {
            files.push(p);
        }
    }
    files.sort();
    if files.is_empty() {
        return Err(Error::input(
            path,
            "rosbag2 directory has no .mcap or .db3 storage file",
        ));
    }
    let mut topics: BTreeMap<String, TopicInfo> = BTreeMap::new();
    let mut out = Recording::default();
    for file in &files {
        let rec = read_storage(file, want)?;
        for t in rec.topics {
            match topics.get_mut(&t.topic) {
                Some(have) => have.count = have.count.zip(t.count).map(|(a, b)| a + b),
                None => {
                    topics.insert(t.topic.clone(), t);
                }
            }
        }
        out.messages.extend(rec.messages);
        out.metadata.extend(rec.metadata);
    }
    out.messages.sort_by_key(|m| m.log_time_ns);
    out.topics = topics.into_values().collect();
    Ok(out)
}

/// One storage file, by extension.
fn read_storage(path: &Path, want: &dyn Fn(&TopicInfo) -> bool) -> Result<Recording> {
    match path.extension().and_then(|e| e.to_str()) {
        Some("db3") => read_db3(path, want),
        Some("mcap") => read_mcap(path, want),
        _ => Err(Error::input(
            path,
            "not a rosbag2 directory, .db3 or .mcap file",
        )),
    }
}

/// A rosbag2 sqlite3 storage file: tables `topics(id, name, type, serialization_format, …)` and
/// `messages(id, topic_id, timestamp, data)`.
fn read_db3(path: &Path, want: &dyn Fn(&TopicInfo) -> bool) -> Result<Recording> {
    // Opening read-only does not create a missing file, but its error would not say so clearly.
    std::fs::metadata(path).map_err(Error::io(path))?;
    let sql = |e: rusqlite::Error| Error::input(path, format!("rosbag2 sqlite3 storage: {e}"));
    let db = Connection::open_with_flags(
        path,
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(sql)?;

    let mut counts: BTreeMap<i64, u64> = BTreeMap::new();
    let mut stmt = db
        .prepare("SELECT topic_id, COUNT(*) FROM messages GROUP BY topic_id")
        .map_err(sql)?;
    let rows = stmt
        .query_map([], |r| Ok((r.get::<_, i64>(0)?, r.get::<_, i64>(1)?)))
        .map_err(sql)?;
    for row in rows {
        let (id, n) = row.map_err(sql)?;
        counts.insert(id, u64::try_from(n).unwrap_or(0));
    }

    // Topic ids of wanted topics → (topic, type); the same name may appear with several ids.
    let mut topics: BTreeMap<String, TopicInfo> = BTreeMap::new();
    let mut wanted: BTreeMap<i64, (String, String)> = BTreeMap::new();
    let mut stmt = db
        .prepare("SELECT id, name, type, serialization_format FROM topics ORDER BY id")
        .map_err(sql)?;
    let rows = stmt
        .query_map([], |r| {
            Ok((
                r.get::<_, i64>(0)?,
                r.get::<_, String>(1)?,
                r.get::<_, String>(2)?,
                r.get::<_, String>(3)?,
            ))
        })
        .map_err(sql)?;
    for row in rows {
        let (id, name, ty, format) = row.map_err(sql)?;
        let info = TopicInfo {
            topic: name.clone(),
            message_type: ros2_type_name(&ty),
            count: Some(counts.get(&id).copied().unwrap_or(0)),
        };
        if want(&info) {
            if format != "cdr" {
                return Err(Error::input(
                    path,
                    format!("topic {name} has serialization format '{format}', expected 'cdr'"),
                ));
            }
            wanted.insert(id, (info.topic.clone(), info.message_type.clone()));
        }
        match topics.get_mut(&name) {
            Some(have) => have.count = have.count.zip(info.count).map(|(a, b)| a + b),
            None => {
                topics.insert(name, info);
            }
        }
    }

    let mut messages = Vec::new();
    if !wanted.is_empty() {
        // The ids are integers read from the file, so formatting them into the query is safe.
        let ids: Vec<String> = wanted.keys().map(i64::to_string).collect();
        let query = format!(
            "SELECT topic_id, timestamp, data FROM messages WHERE topic_id IN ({}) ORDER BY timestamp, id",
            ids.join(",")
        );
        let mut stmt = db.prepare(&query).map_err(sql)?;
        let mut rows = stmt.query([]).map_err(sql)?;
        while let Some(row) = rows.next().map_err(sql)? {
            let id: i64 = row.get(0).map_err(sql)?;
            let ts: i64 = row.get(1).map_err(sql)?;
            let data: Vec<u8> = row.get(2).map_err(sql)?;
            let Some((topic, message_type)) = wanted.get(&id) else {
                continue;
            };
            let log_time_ns = u64::try_from(ts)
                .map_err(|_| Error::input(path, format!("{topic}: negative timestamp {ts}")))?;
            messages.push(RawMessage {
                topic: topic.clone(),
                message_type: message_type.clone(),
                log_time_ns,
                data,
                serialization: Serialization::Cdr,
            });
        }
    }
    Ok(Recording {
        topics: topics.into_values().collect(),
        messages,
        metadata: BTreeMap::new(),
    })
}
