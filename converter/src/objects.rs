//! Inputs in object storage: `s3://bucket/prefix/` listed into recordings the way a local
//! directory is walked (`.mcap`, `.bag` and `.db3` objects; a prefix holding `metadata.yaml` is
//! one rosbag2 directory; `*.partial` objects and `discarded/` prefixes skipped), each input
//! remembered with the sizes and ETags the listing gave (its version: reads are pinned to it,
//! and a re-run skips an input converted before by that version without reading it).
//!
//! MCAP objects are read by range where they are (see [`crate::mcap_remote`]). ROS 1 bags,
//! `.db3` files and rosbag2 directories are downloaded whole into the work directory first:
//! SQLite reads a file, and a bag's chunks interleave every topic, so a ranged read would fetch
//! nearly all of it anyway.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use scaledp_store::{Bucket, Location, ObjectInfo, ObjectUrl};

use crate::error::{Error, Result};

/// One input of a job.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Input {
    /// A local file or rosbag2 directory.
    Local(PathBuf),
    /// An object, or the objects of a rosbag2 directory, as listed.
    Object(ObjectInput),
}

/// An input in object storage.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObjectInput {
    /// The object, or the rosbag2 directory's prefix (without a trailing `/`).
    pub url: ObjectUrl,
    /// The object, or the directory's files (directly under it), as listed.
    pub objects: Vec<ObjectInfo>,
    /// A rosbag2 directory.
    pub directory: bool,
}

impl Input {
    /// The input's path, or its URL as a path: how reports, errors and the dataset name it.
    pub fn name(&self) -> PathBuf {
        match self {
            Input::Local(p) => p.clone(),
            Input::Object(o) => o.url.as_path(),
        }
    }

    /// Its bytes.
    pub fn bytes(&self) -> u64 {
        match self {
            Input::Local(p) => crate::inputs::input_bytes(p),
            Input::Object(o) => o.objects.iter().map(|i| i.size).sum(),
        }
    }

    /// The version of an object input as listed (file names, sizes and ETags), when the store
    /// gives ETags: a re-run skips an input recorded with the same version without reading it.
    pub fn version(&self) -> Option<String> {
        let Input::Object(o) = self else {
            return None;
        };
        let parts: Option<Vec<String>> = o
            .objects
            .iter()
            .map(|i| {
                let etag = i.etag.as_deref()?;
                Some(format!(
                    "{}:{}:{}",
                    i.url.file_name(),
                    i.size,
                    etag.trim_matches('"')
                ))
            })
            .collect();
        parts.map(|p| p.join(";"))
    }
}

/// Whether a name is one of the inputs' extensions.
fn is_input_name(name: &str) -> bool {
    [".mcap", ".bag", ".db3"].iter().any(|e| name.ends_with(e))
}

/// Expands locations into inputs, sorted by name: local paths as [`crate::collect_inputs`]
/// does, URLs by listing their prefix (or naming one object).
pub fn collect(locations: &[Location]) -> Result<Vec<Input>> {
    let mut local = Vec::new();
    let mut out = Vec::new();
    for l in locations {
        match l {
            Location::Local(p) => local.push(p.clone()),
            Location::Object(u) => out.extend(list(u)?),
        }
    }
    out.extend(
        crate::inputs::collect_inputs(&local)?
            .into_iter()
            .map(Input::Local),
    );
    out.sort_by_key(Input::name);
    out.dedup_by_key(|i| i.name());
    Ok(out)
}

/// The inputs under the prefix `url`, or the one object it names.
fn list(url: &ObjectUrl) -> Result<Vec<Input>> {
    let bucket = Bucket::connect(&url.bucket)?;
    let listed = bucket.list(url)?;
    if listed.is_empty() {
        let single = if url.key.is_empty() || url.key.ends_with('/') {
            None
        } else {
            bucket.head(url)?
        };
        let Some(info) = single else {
            return Err(Error::input(
                url.as_path(),
                "no such object, and no object under this prefix",
            ));
        };
        if !is_input_name(url.file_name()) {
            return Err(Error::input(
                url.as_path(),
                "not an .mcap, .bag or .db3 object, nor a prefix",
            ));
        }
        return Ok(vec![Input::Object(ObjectInput {
            url: url.clone(),
            objects: vec![info],
            directory: false,
        })]);
    }
    let prefix = url.prefix();
    let rel = |i: &ObjectInfo| {
        i.url
            .key
            .strip_prefix(&prefix)
            .unwrap_or(&i.url.key)
            .to_string()
    };
    let skipped = |r: &str| r.split('/').rev().skip(1).any(|d| d == "discarded");
    // rosbag2 directories (relative, "" for the prefix itself), outermost first.
    let mut dirs: Vec<String> = Vec::new();
    let candidates: BTreeSet<String> = listed
        .iter()
        .map(&rel)
        .filter(|r| r == "metadata.yaml" || r.ends_with("/metadata.yaml"))
        .map(|r| r.trim_end_matches("metadata.yaml").to_string())
        .filter(|d| !d.split('/').any(|s| s == "discarded"))
        .collect();
    for d in candidates {
        if !dirs.iter().any(|o| d.starts_with(o.as_str())) {
            dirs.push(d);
        }
    }
    let mut out = Vec::new();
    for d in &dirs {
        let objects: Vec<ObjectInfo> = listed
            .iter()
            .filter(|i| {
                rel(i)
                    .strip_prefix(d.as_str())
                    .is_some_and(|f| !f.contains('/'))
            })
            .cloned()
            .collect();
        out.push(Input::Object(ObjectInput {
            url: url.join(d.trim_end_matches('/')),
            objects,
            directory: true,
        }));
    }
    for i in &listed {
        let r = rel(i);
        let in_dir = dirs.iter().any(|d| r.starts_with(d.as_str()));
        if !in_dir && !skipped(&r) && is_input_name(&r) {
            out.push(Input::Object(ObjectInput {
                url: i.url.clone(),
                objects: vec![i.clone()],
                directory: false,
            }));
        }
    }
    Ok(out)
}

/// A local copy of an object input (a `.bag`, a `.db3`, a rosbag2 directory) in a temporary
/// directory under `work_dir`, under the same file or directory name (the content hash
/// includes it). The copy is removed with the returned directory.
pub(crate) fn download(
    input: &ObjectInput,
    work_dir: &Path,
) -> Result<(tempfile::TempDir, PathBuf)> {
    let tmp = tempfile::Builder::new()
        .prefix("scaledp-input-")
        .tempdir_in(work_dir)
        .map_err(Error::io(work_dir))?;
    let bucket = Bucket::connect(&input.url.bucket)?;
    let local = tmp.path().join(input.url.file_name());
    if input.directory {
        std::fs::create_dir(&local).map_err(Error::io(&local))?;
        for o in &input.objects {
            bucket.download(o, &local.join(o.url.file_name()))?;
        }
    } else if let Some(o) = input.objects.first() {
        bucket.download(o, &local)?;
    }
    Ok((tmp, local))
}
