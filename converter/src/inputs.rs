//! The inputs of a job: paths expanded into recordings and bags, the shard of them a job
//! converts, their content hashes (what resuming skips by), and any one of them read whole.

use std::io::Read;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::source::{Recording, TopicInfo};

/// Expands directories into inputs: rosbag2 directories (with `metadata.yaml`), `.mcap`,
/// `.bag` and `.db3` files; skips `*.partial` files and `discarded/` directories. Sorted.
pub fn collect_inputs(paths: &[PathBuf]) -> Result<Vec<PathBuf>> {
    fn walk(p: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
        if p.is_dir() {
            if p.join("metadata.yaml").exists() {
                out.push(p.into());
                return Ok(());
            }
            if p.file_name().is_some_and(|n| n == "discarded") {
                return Ok(());
            }
            for e in std::fs::read_dir(p).map_err(Error::io(p))?.flatten() {
                walk(&e.path(), out)?;
            }
        } else if matches!(
            p.extension().and_then(|e| e.to_str()),
            Some("mcap" | "bag" | "db3")
        ) {
            out.push(p.into());
        }
        Ok(())
    }
    let mut out = Vec::new();
    for p in paths {
        if !p.exists() {
            return Err(Error::input(p, "no such file or directory"));
        }
        if p.is_file()
            && !matches!(
                p.extension().and_then(|e| e.to_str()),
                Some("mcap" | "bag" | "db3")
            )
        {
            return Err(Error::input(
                p,
                "not an .mcap, .bag or .db3 file, nor a directory",
            ));
        }
        walk(p, &mut out)?;
    }
    out.sort();
    out.dedup();
    Ok(out)
}

/// The inputs of shard `i` of `n`: a contiguous slice of the sorted list.
pub fn shard<T>(inputs: &[T], i: usize, n: usize) -> &[T] {
    let len = inputs.len();
    &inputs[len * i / n..len * (i + 1) / n]
}

/// A hasher fed the file name, as [`content_hash`] starts for each file.
pub(crate) fn hasher_for(path: &Path) -> blake3::Hasher {
    let mut h = blake3::Hasher::new();
    h.update(
        path.file_name()
            .map(|n| n.as_encoded_bytes())
            .unwrap_or_default(),
    );
    h
}

/// BLAKE3 of a file, or of a directory's files (names and contents, in name order).
pub fn content_hash(path: &Path) -> Result<String> {
    let mut h = blake3::Hasher::new();
    let mut files = vec![];
    if path.is_dir() {
        let mut entries: Vec<PathBuf> = std::fs::read_dir(path)
            .map_err(Error::io(path))?
            .flatten()
            .map(|e| e.path())
            .collect();
        entries.sort();
        files.extend(entries.into_iter().filter(|p| p.is_file()));
    } else {
        files.push(path.to_path_buf());
    }
    for f in files {
        h.update(
            f.file_name()
                .map(|n| n.as_encoded_bytes())
                .unwrap_or_default(),
        );
        let mut file = std::fs::File::open(&f).map_err(Error::io(&f))?;
        let mut buf = vec![0u8; 1 << 20];
        loop {
            let n = file.read(&mut buf).map_err(Error::io(&f))?;
            if n == 0 {
                break;
            }
            h.update(&buf[..n]);
        }
    }
    Ok(h.finalize().to_hex().to_string())
}

pub(crate) fn input_bytes(path: &Path) -> u64 {
    if path.is_dir() {
        std::fs::read_dir(path)
            .into_iter()
            .flatten()
            .flatten()
            .filter_map(|e| e.metadata().ok())
            .map(|m| m.len())
            .sum()
    } else {
        std::fs::metadata(path).map_or(0, |m| m.len())
    }
}

/// The message types a conversion can use.
pub(crate) fn useful_topic(t: &TopicInfo) -> bool {
    crate::source::is_read(&t.message_type)
}

/// Reads any supported input whole, keeping only the topics a conversion can use.
pub fn read_input(path: &Path) -> Result<Recording> {
    let want = useful_topic;
    if path.is_dir() || path.extension().is_some_and(|e| e == "db3") {
        return crate::read_rosbag2(path, &want);
    }
    match path.extension().and_then(|e| e.to_str()) {
        Some("bag") => crate::read_ros1_bag(path, &want),
        _ => crate::read_mcap(path, &want),
    }
}

pub(crate) fn is_mcap_file(path: &Path) -> bool {
    path.is_file() && path.extension().is_some_and(|e| e == "mcap")
}
