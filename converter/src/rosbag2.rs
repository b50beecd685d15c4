//! rosbag2 input: a bag directory with mcap or sqlite3 (`.db3`) storage files, or a standalone
//! `.db3` file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rusqlite::{Connection, OpenFlags};

use crate::error::{Error, Result};
use crate::mcap_source::read_mcap;
use crate::source::{ros2_type_name, RawMessage, Recording, Serialization, TopicInfo};

/// Reads a rosbag2: either a bag directory (its `metadata.yaml` lists the storage files, `.mcap`
/// or `.db3`, read in that order and merged) or a standalone `.db3` (or `.mcap`) file. Returns
/// its topics (counts summed over the storage files), the messages of the topics `want` accepts
/// sorted by log time, and the metadata records of mcap storage.
///
/// Of `metadata.yaml` only `relative_file_paths` is read (see [`storage_files`]): every path must
/// stay inside the bag directory and exist. For split bags `want` sees each file's topics with
/// that file's counts. Compressed storage files (`.mcap.zstd`, `.db3.zstd`) are rejected with a
/// hint. sqlite3 topics must be `cdr`-serialized.
pub fn read_rosbag2(path: &Path, want: &dyn Fn(&TopicInfo) -> bool) -> Result<Recording> {
    let meta = std::fs::metadata(path).map_err(Error::io(path))?;
    if !meta.is_dir() {
        return read_storage(path, want);
    }
    let files = storage_files(path)?;
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

/// The storage files a bag directory's `metadata.yaml` lists in `relative_file_paths`, checked:
/// the file is rosbag2 metadata, each path is relative and stays inside the directory, each
/// file exists and is not compressed.
///
/// rosbag2 (yaml-cpp) and `rosbags` write the block style `relative_file_paths:` then one
/// `- name` line per file; a flow list `[a, b]` is read too. Nothing else of the file is parsed:
/// the storage files hold everything the converter needs.
fn storage_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let yaml = dir.join("metadata.yaml");
    if !yaml.is_file() {
        return Err(Error::input(
            dir,
            "not a rosbag2 directory (no metadata.yaml)",
        ));
    }
    let text = std::fs::read_to_string(&yaml).map_err(Error::io(&yaml))?;
    let names = relative_file_paths(&text).map_err(|reason| Error::input(&yaml, reason))?;
    if let Some(format) = compression_format(&text) {
        return Err(Error::input(
            &yaml,
            format!(
                "compressed rosbag2 storage (compression_format: {format}) is not supported; \
                 decompress it first (`ros2 bag convert`)"
            ),
        ));
    }
    let mut files = Vec::with_capacity(names.len());
    for name in names {
        let mut rel = Path::new(&name);
        // Bags of metadata version < 4 (ROS 2 Foxy) list paths from the bag's parent
        // directory: `bag/bag_0.db3`.
        if let Ok(inner) = rel.strip_prefix(dir.file_name().unwrap_or_default()) {
            if !dir.join(rel).exists() && dir.join(inner).is_file() {
                rel = inner;
            }
        }
        let inside = rel
            .components()
            .all(|c| matches!(c, std::path::Component::Normal(_)));
        if !inside {
            return Err(Error::input(
                &yaml,
                format!("storage file '{name}' is outside the bag directory"),
            ));
        }
        let p = dir.join(rel);
        if name.ends_with(".mcap.zstd") || name.ends_with(".db3.zstd") {
            return Err(Error::input(
                &p,
                "compressed rosbag2 storage is not supported; decompress it first (`ros2 bag convert`)",
            ));
        }
        if !p.is_file() {
            return Err(Error::input(
                &yaml,
                format!("lists storage file '{name}', which is missing"),
            ));
        }
        files.push(p);
    }
    Ok(files)
}

/// The `compression_format` of rosbag2 metadata, when it names one (file or message
/// compression).
fn compression_format(text: &str) -> Option<String> {
    text.lines()
        .find_map(|l| l.trim_start().strip_prefix("compression_format:"))
        .map(|v| v.trim().trim_matches(|c| c == '\'' || c == '"').to_string())
        .filter(|v| !v.is_empty())
}

/// The `relative_file_paths` of rosbag2 metadata (see [`storage_files`]).
pub(crate) fn relative_file_paths(text: &str) -> std::result::Result<Vec<String>, String> {
    let mut lines = text
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    if !lines
        .next()
        .is_some_and(|l| l.starts_with("rosbag2_bagfile_information:"))
    {
        return Err(
            "not rosbag2 metadata (it must start with 'rosbag2_bagfile_information:')".into(),
        );
    }
    let unquote = |s: &str| s.trim().trim_matches(|c| c == '\'' || c == '"').to_string();
    let mut names = Vec::new();
    let mut lines = text.lines().peekable();
    while let Some(line) = lines.next() {
        let Some(rest) = line.trim_start().strip_prefix("relative_file_paths:") else {
            continue;
        };
        let rest = rest.trim();
        if let Some(flow) = rest.strip_prefix('[') {
            let flow = flow
                .strip_suffix(']')
                .ok_or("relative_file_paths: unterminated list")?;
            names.extend(flow.split(',').map(unquote).filter(|n| !n.is_empty()));
        } else if !rest.is_empty() {
            return Err(format!("relative_file_paths: unexpected '{rest}'"));
        }
        let indent = line.len() - line.trim_start().len();
        while let Some(item) = lines.peek() {
            let at = item.len() - item.trim_start().len();
            match item.trim_start().strip_prefix('-') {
                Some(name) if at >= indent => names.push(unquote(name)),
                _ => break,
            }
            lines.next();
        }
        break;
    }
    if names.is_empty() {
        return Err("lists no storage files (relative_file_paths)".into());
    }
    Ok(names)
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
