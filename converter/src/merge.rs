//! `dataset merge`: joins scaledp datasets (the shards of one job) into one, local or in
//! object storage, giving the same files as one run over all their inputs. A dataset in object
//! storage is read through its record and one data file at a time, downloaded into the work
//! directory; the merged dataset is written like a job's (see [`crate::destination`]).

use std::path::{Path, PathBuf};

use scaledp_store::{Bucket, Location, ObjectUrl};

use crate::destination::Destination;
use crate::error::{Error, Result};
use crate::lerobot::{data_path, Sidecar};

/// Settings of a merge, set with chained setters. Defaults: data files of 100 MiB, every input
/// must hold a dataset, the system's temporary directory as work directory.
#[derive(Debug, Clone)]
pub struct MergeOptions {
    file_size_mib: u64,
    skip_empty: bool,
    work_dir: Option<PathBuf>,
}

impl Default for MergeOptions {
    fn default() -> Self {
        Self {
            file_size_mib: 100,
            skip_empty: false,
            work_dir: None,
        }
    }
}

impl MergeOptions {
    /// Data file size target in MiB.
    pub fn file_size_mib(mut self, mib: u64) -> Self {
        self.file_size_mib = mib;
        self
    }
    /// Skips (and reports) inputs that hold nothing at all, as a shard with no inputs leaves,
    /// instead of failing on them; an input holding something else than a dataset still fails.
    pub fn skip_empty(mut self, yes: bool) -> Self {
        self.skip_empty = yes;
        self
    }
    /// Where downloads and the working copy of an object-storage output go.
    pub fn work_dir(mut self, dir: impl Into<PathBuf>) -> Self {
        self.work_dir = Some(dir.into());
        self
    }
}

/// What a merge did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MergeSummary {
    /// Episodes in the merged dataset.
    pub episodes: usize,
    /// Inputs skipped as empty (with [`MergeOptions::skip_empty`]).
    pub empty: Vec<Location>,
}

/// Joins scaledp datasets (e.g. the outputs of `--shard 0/N … N-1/N`) into `out`, in the order
/// given, re-indexing episodes, frames and tasks and re-aggregating statistics; data files of
/// `file_size_mib` MiB. Returns the number of episodes.
pub fn merge(inputs: &[PathBuf], out: &Path, file_size_mib: u64) -> Result<usize> {
    let inputs: Vec<Location> = inputs.iter().cloned().map(Location::Local).collect();
    let opts = MergeOptions::default().file_size_mib(file_size_mib);
    Ok(merge_datasets(&inputs, &Location::Local(out.into()), &opts)?.episodes)
}

/// [`merge`] for datasets anywhere: local directories or object-storage prefixes; `out` is
/// replaced.
pub fn merge_datasets(
    inputs: &[Location],
    out: &Location,
    opts: &MergeOptions,
) -> Result<MergeSummary> {
    let work_dir = opts.work_dir.clone().unwrap_or_else(std::env::temp_dir);
    let mut dest = Destination::open(out, true, opts.file_size_mib, &work_dir)?;
    let mut summary = MergeSummary {
        episodes: 0,
        empty: Vec::new(),
    };
    for input in inputs {
        let Some(source) = Source::open(input, &work_dir, opts.skip_empty)? else {
            tracing::warn!("{input}: holds nothing (a shard without inputs?); skipped");
            summary.empty.push(input.clone());
            continue;
        };
        for ep in &source.sidecar.episodes {
            let root = source.data_file(ep.data_file)?;
            dest.dataset().add_from(&root, &source.sidecar, ep)?;
            dest.committed()?;
            summary.episodes += 1;
        }
    }
    dest.finish()?;
    Ok(summary)
}

/// One dataset merged: its record, and its data files (downloaded one at a time for object
/// storage).
struct Source {
    sidecar: Sidecar,
    remote: Option<(std::sync::Arc<Bucket>, ObjectUrl, tempfile::TempDir)>,
    local: PathBuf,
}

impl Source {
    /// None for an empty input when `skip_empty`.
    fn open(input: &Location, work_dir: &Path, skip_empty: bool) -> Result<Option<Self>> {
        let record = "meta/scaledp.json";
        let parse = |path: PathBuf, bytes: &[u8]| -> Result<Sidecar> {
            serde_json::from_slice(bytes)
                .map_err(|e| Error::input(path, format!("unreadable: {e}")))
        };
        let missing = |path: PathBuf| {
            Error::input(
                path,
                "no scaledp dataset here (meta/scaledp.json is missing)",
            )
        };
        match input {
            Location::Local(root) => {
                let path = root.join(record);
                match std::fs::read(&path) {
                    Ok(bytes) => Ok(Some(Self {
                        sidecar: parse(path, &bytes)?,
                        remote: None,
                        local: root.clone(),
                    })),
                    Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                        let empty =
                            std::fs::read_dir(root).map_or(true, |mut d| d.next().is_none());
                        if skip_empty && empty {
                            return Ok(None);
                        }
                        Err(missing(path))
                    }
                    Err(e) => Err(Error::io(path)(e)),
                }
            }
            Location::Object(url) => {
                let bucket = Bucket::connect(&url.bucket)?;
                let Some(bytes) = bucket.get(&url.join(record))? else {
                    if skip_empty && bucket.list(url)?.is_empty() {
                        return Ok(None);
                    }
                    return Err(missing(url.join(record).as_path()));
                };
                let tmp = tempfile::Builder::new()
                    .prefix("scaledp-merge-")
                    .tempdir_in(work_dir)
                    .map_err(Error::io(work_dir))?;
                Ok(Some(Self {
                    sidecar: parse(url.join(record).as_path(), &bytes)?,
                    local: tmp.path().to_path_buf(),
                    remote: Some((bucket, url.clone(), tmp)),
                }))
            }
        }
    }

    /// The root under which data file `n` is, downloading it (and dropping the one before)
    /// for object storage.
    fn data_file(&self, n: u64) -> Result<PathBuf> {
        let Some((bucket, url, _)) = &self.remote else {
            return Ok(self.local.clone());
        };
        let path = data_path(&self.local, n);
        if !path.exists() {
            let data = self.local.join("data");
            if data.exists() {
                std::fs::remove_dir_all(&data).map_err(Error::io(&data))?;
            }
            if let Some(dir) = path.parent() {
                std::fs::create_dir_all(dir).map_err(Error::io(dir))?;
            }
            let rel = data_path(Path::new(""), n);
            let object = url.join(&rel.to_string_lossy());
            let info = bucket.head(&object)?.ok_or_else(|| {
                Error::input(
                    object.as_path(),
                    "data file listed by meta/scaledp.json is missing",
                )
            })?;
            bucket.download(&info, &path)?;
        }
        Ok(self.local.clone())
    }
}
