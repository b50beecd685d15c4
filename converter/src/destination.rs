//! Where a job writes its dataset: a local directory (the dataset itself, see
//! [`crate::lerobot`]), or a prefix in object storage, written through a local working copy so
//! that nothing partial is ever visible there:
//!
//! - at the start, the destination's `meta/scaledp.json` (the dataset already there) and the
//!   checkpoint of a killed run are read, and `.scaledp-staging/job.json` is written: a missing
//!   bucket, refused credentials or a bucket that denies writes stop the job before any work;
//! - each data file, once complete, is uploaded (multipart) under `.scaledp-staging/data/…`
//!   and removed locally, then the checkpoint (`.scaledp-staging/checkpoint.json`: the record of
//!   every episode whose data file is staged) is rewritten, so a killed job's re-run resumes
//!   from it by content hash;
//! - at the end the last data file is staged, the staged files are copied (server side) to
//!   `data/…`, the meta files are uploaded with `meta/info.json` last, objects no episode lists
//!   any more are deleted, and the staging prefix is removed.
//!
//! Until `meta/info.json` is written a reader sees the previous dataset unchanged (new data
//! files have new numbers; meta is rewritten whole), or no dataset; with `--overwrite` the old
//! `meta/info.json` is deleted first. One job writes to one destination at a time (shards
//! write to their own prefixes and are merged).

use std::collections::BTreeSet;
use std::path::Path;
use std::sync::Arc;

use scaledp_store::{Bucket, Location, ObjectUrl};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::lerobot::{data_path, Dataset, Sidecar};

/// The staging prefix, under the destination.
const STAGING: &str = ".scaledp-staging";

/// The checkpoint of a job writing to object storage.
#[derive(Debug, Serialize, Deserialize)]
struct Checkpoint {
    format: u32,
    /// The job replaces the dataset at the destination (`--overwrite`, or a merge).
    replace: bool,
    /// Every episode whose data file is staged or published.
    sidecar: Sidecar,
}

/// A dataset being written, locally or to object storage.
pub(crate) enum Destination {
    /// A local directory.
    Local(Box<Dataset>),
    /// A prefix in object storage.
    Object(Box<ObjectDestination>),
}

/// A dataset written to object storage through a local working copy.
pub(crate) struct ObjectDestination {
    dataset: Dataset,
    _work: tempfile::TempDir,
    bucket: Arc<Bucket>,
    url: ObjectUrl,
    /// The dataset's record at the destination when the job started (None: none there).
    published: Option<Sidecar>,
    replace: bool,
    /// Data files staged (by this run or the killed run it resumes).
    staged: BTreeSet<u64>,
}

/// The data file numbers `s` lists.
fn files_of(s: Option<&Sidecar>) -> BTreeSet<u64> {
    s.map(|s| s.episodes.iter().map(|e| e.data_file).collect())
        .unwrap_or_default()
}

/// `data/chunk-XXX/file-YYY.parquet` of file `n`, relative.
fn data_key(n: u64) -> String {
    data_path(Path::new(""), n).to_string_lossy().into_owned()
}

impl Destination {
    /// Opens the dataset at `out` (emptied first with `overwrite`; see the module docs for
    /// object storage, whose working copy goes under `work_dir`).
    pub fn open(
        out: &Location,
        overwrite: bool,
        file_size_mib: u64,
        work_dir: &Path,
    ) -> Result<Self> {
        match out {
            Location::Local(root) => Ok(Self::Local(Box::new(Dataset::open(
                root,
                overwrite,
                file_size_mib,
            )?))),
            Location::Object(url) => Ok(Self::Object(Box::new(ObjectDestination::open(
                url,
                overwrite,
                file_size_mib,
                work_dir,
            )?))),
        }
    }

    /// The dataset (the working copy for object storage).
    pub fn dataset(&mut self) -> &mut Dataset {
        match self {
            Self::Local(d) => d,
            Self::Object(o) => &mut o.dataset,
        }
    }

    /// After each committed episode: stages the data files that are complete.
    pub fn committed(&mut self) -> Result<()> {
        match self {
            Self::Local(_) => Ok(()),
            Self::Object(o) => o.stage(false),
        }
    }

    /// Makes the dataset visible at the destination (see the module docs).
    pub fn finish(self) -> Result<()> {
        match self {
            Self::Local(_) => Ok(()),
            Self::Object(o) => o.publish(),
        }
    }
}

impl ObjectDestination {
    fn open(url: &ObjectUrl, overwrite: bool, file_size_mib: u64, work_dir: &Path) -> Result<Self> {
        let bucket = Bucket::connect(&url.bucket)?;
        let read = |rel: &str| -> Result<Option<bytes::Bytes>> { Ok(bucket.get(&url.join(rel))?) };
        let published: Option<Sidecar> = match read("meta/scaledp.json")? {
            Some(b) => Some(parse(url, "meta/scaledp.json", &b)?),
            None if bucket.head(&url.join("meta/info.json"))?.is_some() => {
                return Err(Error::Dataset {
                    path: url.as_path(),
                    reason: "a LeRobot dataset not written by scaledp; convert into a new prefix"
                        .into(),
                })
            }
            None => None,
        };
        let checkpoint_key = format!("{STAGING}/checkpoint.json");
        let checkpoint: Option<Checkpoint> = match read(&checkpoint_key)? {
            Some(b) => Some(parse(url, &checkpoint_key, &b)?),
            None => None,
        };
        // Write access before any work.
        let job = serde_json::json!({
            "pid": std::process::id(),
            "host": std::env::var("HOSTNAME").unwrap_or_default(),
            "started_unix_s": std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs()),
        });
        bucket.put(
            &url.join(&format!("{STAGING}/job.json")),
            serde_json::to_vec(&job).unwrap_or_default().into(),
        )?;
        let extends = |c: &Checkpoint| {
            c.replace
                || published.as_ref().is_none_or(|p| {
                    c.sidecar.episodes.len() >= p.episodes.len()
                        && c.sidecar.episodes[..p.episodes.len()] == p.episodes[..]
                })
        };
        let (replace, start) = match checkpoint {
            _ if overwrite => (true, None),
            Some(c) if extends(&c) => {
                tracing::info!(
                    "{url}: resuming from the checkpoint of an interrupted job ({} episodes)",
                    c.sidecar.episodes.len()
                );
                (c.replace, Some(c.sidecar))
            }
            Some(_) => {
                tracing::warn!(
                    "{url}: a stale checkpoint (the dataset changed since) is discarded"
                );
                (false, published.clone())
            }
            None => (false, published.clone()),
        };
        let mut staged = files_of(start.as_ref());
        if !replace {
            staged = &staged - &files_of(published.as_ref());
        }
        let work = tempfile::Builder::new()
            .prefix("scaledp-dataset-")
            .tempdir_in(work_dir)
            .map_err(Error::io(work_dir))?;
        let dataset = Dataset::continue_from(work.path(), start, file_size_mib)?;
        let d = Self {
            dataset,
            _work: work,
            bucket,
            url: url.clone(),
            published,
            replace,
            staged,
        };
        if overwrite {
            d.clear_staging(true)?;
        }
        Ok(d)
    }

    fn staging(&self, rel: &str) -> ObjectUrl {
        self.url.join(&format!("{STAGING}/{rel}"))
    }

    /// Uploads the complete data files (with `all`, the open one too) and rewrites the
    /// checkpoint when any was uploaded.
    fn stage(&mut self, all: bool) -> Result<()> {
        let open = self.dataset.open_file().filter(|_| !all);
        let published = if self.replace {
            BTreeSet::new()
        } else {
            files_of(self.published.as_ref())
        };
        let pending: Vec<u64> = files_of(self.dataset.sidecar())
            .into_iter()
            .filter(|n| Some(*n) != open && !self.staged.contains(n) && !published.contains(n))
            .collect();
        for &n in &pending {
            let local = data_path(self.dataset.root(), n);
            let bytes = self.bucket.upload(&local, &self.staging(&data_key(n)))?;
            tracing::debug!("{}: staged {bytes} bytes", self.staging(&data_key(n)));
            std::fs::remove_file(&local).map_err(Error::io(&local))?;
            self.staged.insert(n);
        }
        if pending.is_empty() {
            return Ok(());
        }
        let Some(s) = self.dataset.sidecar() else {
            return Ok(());
        };
        let mut done = s.clone();
        done.episodes
            .retain(|e| self.staged.contains(&e.data_file) || published.contains(&e.data_file));
        let tasks = done
            .episodes
            .iter()
            .map(|e| e.task_index + 1)
            .max()
            .unwrap_or(0);
        done.tasks.truncate(tasks as usize);
        let checkpoint = Checkpoint {
            format: 1,
            replace: self.replace,
            sidecar: done,
        };
        let json = serde_json::to_vec(&checkpoint).unwrap_or_default();
        self.bucket
            .put(&self.staging("checkpoint.json"), json.into())?;
        Ok(())
    }

    /// Deletes the staging prefix (with `keep_job`, all but the job marker).
    fn clear_staging(&self, keep_job: bool) -> Result<()> {
        let job = self.staging("job.json");
        let listed = self.bucket.list(&self.url.join(STAGING))?;
        let doomed: Vec<ObjectUrl> = listed
            .into_iter()
            .map(|i| i.url)
            .filter(|u| !(keep_job && *u == job))
            .collect();
        Ok(self.bucket.delete(&doomed)?)
    }

    fn publish(mut self) -> Result<()> {
        self.stage(true)?;
        if !self.replace && self.dataset.sidecar() == self.published.as_ref() {
            // Nothing new: the published dataset stays as it is.
            return self.clear_staging(false);
        }
        let Some(s) = self.dataset.sidecar().cloned() else {
            // Nothing converted: the destination keeps what it had (with --overwrite: nothing).
            if self.replace {
                self.delete_unlisted(&BTreeSet::new())?;
            }
            return self.clear_staging(false);
        };
        self.dataset.write_meta()?;
        let meta_root = self.dataset.root().join("meta");
        let mut meta = Vec::new();
        walk(&meta_root, &mut meta)?;
        let meta_keys: Vec<String> = meta
            .iter()
            .filter_map(|p| p.strip_prefix(self.dataset.root()).ok())
            .map(|p| p.to_string_lossy().into_owned())
            .collect();
        let mut keep: BTreeSet<String> = files_of(Some(&s)).into_iter().map(data_key).collect();
        keep.extend(meta_keys.iter().cloned());
        if self.replace {
            self.bucket.delete(&[self.url.join("meta/info.json")])?;
        }
        for &n in &self.staged {
            self.bucket
                .copy(&self.staging(&data_key(n)), &self.url.join(&data_key(n)))?;
        }
        if self.replace {
            self.delete_unlisted(&keep)?;
        }
        let info = "meta/info.json";
        let ordered = meta_keys
            .iter()
            .zip(&meta)
            .filter(|(k, _)| k.as_str() != info)
            .chain(
                meta_keys
                    .iter()
                    .zip(&meta)
                    .filter(|(k, _)| k.as_str() == info),
            );
        for (key, path) in ordered {
            self.bucket.upload(path, &self.url.join(key))?;
        }
        if !self.replace {
            self.delete_unlisted(&keep)?;
        }
        self.clear_staging(false)
    }

    /// Deletes the objects under `data/` and `meta/` whose relative keys `keep` does not hold.
    fn delete_unlisted(&self, keep: &BTreeSet<String>) -> Result<()> {
        let mut doomed = Vec::new();
        for dir in ["data", "meta"] {
            for i in self.bucket.list(&self.url.join(dir))? {
                let rel = i
                    .url
                    .key
                    .strip_prefix(&self.url.prefix())
                    .unwrap_or_default();
                if !keep.contains(rel) {
                    doomed.push(i.url.clone());
                }
            }
        }
        if !doomed.is_empty() {
            tracing::info!(
                "{}: removing {} objects no episode lists",
                self.url,
                doomed.len()
            );
        }
        Ok(self.bucket.delete(&doomed)?)
    }
}

/// The JSON object `rel` under `url`.
fn parse<T: serde::de::DeserializeOwned>(url: &ObjectUrl, rel: &str, bytes: &[u8]) -> Result<T> {
    serde_json::from_slice(bytes)
        .map_err(|e| Error::input(url.join(rel).as_path(), format!("unreadable: {e}")))
}

/// Every file under `dir`, recursively, sorted.
fn walk(dir: &Path, out: &mut Vec<std::path::PathBuf>) -> Result<()> {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .map_err(Error::io(dir))?
        .flatten()
        .map(|e| e.path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            walk(&p, out)?;
        } else if p.extension().is_none_or(|e| e != "tmp") {
            out.push(p);
        }
    }
    Ok(())
}
