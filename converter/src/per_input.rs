//! One input of a job, converted: a local file or directory read as it is, an MCAP object
//! read by range (its outcome checked from its metadata record before its chunks are read),
//! any other object downloaded into the work directory first. An input already in the dataset
//! (by content hash, or for an object by the version it was read at) is skipped; a panic while
//! converting one (a bug, never bad input) fails that input alone.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use scaledp_schema::Label;
use scaledp_store::Bucket;

use crate::episode::{convert, Episode};
use crate::error::Error;
use crate::frames::{read_mcap_from, FrameStore, InMemory, McapSource};
use crate::inputs::{content_hash, hasher_for, is_mcap_file, read_input, useful_topic};
use crate::lerobot::EpisodeRecord;
use crate::mcap_remote::RemoteMcap;
use crate::objects::{download, Input, ObjectInput};
use crate::options::{ConvertOptions, JobOptions, Unlabeled};
use crate::source::Recording;

/// What happened to one input of a [`crate::run`].
#[derive(Debug)]
pub enum InputResult {
    /// Converted and committed (several episodes when the input was split on time gaps).
    Converted(Vec<EpisodeRecord>),
    /// Already in the dataset (same content hash), or excluded by its recorded outcome: why.
    Skipped(String),
    /// Could not be converted; the error names the file and the reason
    /// ([`Error::one_line`] for a report).
    Failed(Error),
}

/// Log-time windows `[start, end)` separated by gaps longer than `gap_s` (one window, all of
/// the input, without a gap setting).
fn windows(
    rec: &Recording,
    frames: &dyn FrameStore,
    gap_s: Option<f64>,
) -> Vec<Option<(u64, u64)>> {
    let Some(gap_s) = gap_s else {
        return vec![None];
    };
    let mut times: Vec<u64> = rec.messages.iter().map(|m| m.log_time_ns).collect();
    for t in &rec.topics {
        times.extend(frames.stamps(&t.topic).into_iter().map(|(_, log)| log));
    }
    times.sort_unstable();
    times.dedup();
    let (Some(&first), Some(&last)) = (times.first(), times.last()) else {
        return vec![None];
    };
    let gap_ns = (gap_s * 1e9) as u64;
    let mut out = Vec::new();
    let mut start = first;
    for w in times.windows(2) {
        if w[1] - w[0] > gap_ns {
            out.push(Some((start, w[0] + 1)));
            start = w[1];
        }
    }
    out.push(Some((start, last + 1)));
    out
}

/// An input's episodes, or why there are none.
pub(crate) type Episodes = std::result::Result<Vec<Episode>, InputResult>;

/// True when the input with content hash `h` is in the dataset whole: as one episode, or as
/// every part `h#k/n` of a split.
fn fully_converted(existing: &[String], h: &str) -> bool {
    if existing.iter().any(|e| e == h) {
        return true;
    }
    let prefix = format!("{h}#");
    let parts: Vec<&str> = existing
        .iter()
        .filter_map(|e| e.strip_prefix(&prefix))
        .collect();
    let n = parts
        .first()
        .and_then(|p| p.split_once('/'))
        .and_then(|(_, n)| n.parse::<usize>().ok());
    n.is_some_and(|n| (0..n).all(|k| parts.contains(&format!("{k}/{n}").as_str())))
}

/// The episodes of a recording read from `path` (the input `name`, which the episodes' sources
/// and errors name), one per `--split-gap` window.
fn convert_recording(
    path: &Path,
    name: &Path,
    rec: &Recording,
    frames: &dyn FrameStore,
    opts: &JobOptions,
) -> Episodes {
    let failed = |e: Error| InputResult::Failed(e.renamed(path, name));
    check_outcome(name, rec, opts)?;
    let parts = windows(rec, frames, opts.split_gap_s);
    let split = parts.len() > 1;
    let mut episodes = Vec::with_capacity(parts.len());
    for (k, window) in parts.into_iter().enumerate() {
        let copts = ConvertOptions {
            window_ns: window,
            ..opts.convert.clone()
        };
        let mut ep = convert(path, rec, frames, &copts).map_err(failed)?;
        let mut source = name.as_os_str().to_owned();
        if split {
            source.push(format!("#{k}"));
        }
        ep.source = source.into();
        episodes.push(ep);
    }
    Ok(episodes)
}

/// Converts one local input; for an MCAP file with `hash`, also returns its [`content_hash`],
/// taken during the one read (no second pass over the file).
fn convert_one(path: &Path, opts: &JobOptions, hash: bool) -> (Episodes, Option<String>) {
    let failed = InputResult::Failed;
    let run =
        |rec: &Recording, frames: &dyn FrameStore| convert_recording(path, path, rec, frames, opts);
    if is_mcap_file(path) {
        // Without a split, frames are encoded during the one read (see `crate::prefetch`).
        let prefetch = opts.split_gap_s.is_none().then_some(&opts.convert);
        let mut hasher = hash.then(|| hasher_for(path));
        let read = crate::frames::read_mcap_hashed(path, &useful_topic, prefetch, hasher.as_mut());
        let converted = match read {
            Ok((rec, frames)) => run(&rec, &frames),
            Err(e) => Err(failed(e)),
        };
        return (converted, hasher.map(|h| h.finalize().to_hex().to_string()));
    }
    let converted = read_input(path)
        .map_err(failed)
        .and_then(|rec| run(&rec, &InMemory(&rec)));
    (converted, None)
}

/// Converts one object input and returns its content hash (taken on the way: the whole
/// object is read either way).
fn convert_object(o: &ObjectInput, opts: &JobOptions) -> (Episodes, Option<String>) {
    let name = o.url.as_path();
    let failed = |e: Error| (Err(InputResult::Failed(e)), None);
    let mcap = !o.directory && o.url.file_name().ends_with(".mcap");
    let Some(info) = o.objects.first().filter(|_| mcap) else {
        let (_tmp, local) = match download(o, &opts.work_dir_or_temp()) {
            Ok(d) => d,
            Err(e) => return failed(e),
        };
        let hash = match content_hash(&local) {
            Ok(h) => h,
            Err(e) => return failed(e.renamed(&local, &name)),
        };
        let converted = read_input(&local)
            .map_err(|e| InputResult::Failed(e.renamed(&local, &name)))
            .and_then(|rec| convert_recording(&local, &name, &rec, &InMemory(&rec), opts));
        return (converted, Some(hash));
    };
    let remote = match Bucket::connect(&o.url.bucket)
        .map_err(Error::from)
        .and_then(|b| RemoteMcap::open(b, info.clone()))
    {
        Ok(r) => r,
        Err(e) => return failed(e),
    };
    // An episode recorded as failed or discarded is skipped before its chunks are read.
    match remote.metadata() {
        Ok(Some(metadata)) => {
            let rec = Recording {
                metadata,
                ..Recording::default()
            };
            if let Err(skip) = check_outcome(&name, &rec, opts) {
                return (Err(skip), None);
            }
        }
        Ok(None) => {}
        Err(e) => return failed(e),
    }
    let prefetch = opts.split_gap_s.is_none().then_some(&opts.convert);
    let mut hasher = hasher_for(&name);
    let source = McapSource::Object(Arc::new(remote));
    let read = read_mcap_from(&name, source, &useful_topic, prefetch, Some(&mut hasher));
    let converted = match read {
        Ok((rec, frames)) => convert_recording(&name, &name, &rec, &frames, opts),
        Err(e) => Err(InputResult::Failed(e)),
    };
    (converted, Some(hasher.finalize().to_hex().to_string()))
}

/// What the dataset already holds: content hashes, and for objects the version each was read
/// at (mapped to its hash).
pub(crate) struct Existing {
    pub hashes: Vec<String>,
    pub versions: HashMap<String, String>,
}

impl Existing {
    /// Of the committed episodes `records`.
    pub fn of(records: &[EpisodeRecord]) -> Self {
        let base = |h: &str| h.split('#').next().unwrap_or(h).to_string();
        Self {
            hashes: records.iter().map(|e| e.source_hash.clone()).collect(),
            versions: records
                .iter()
                .filter_map(|e| Some((e.source_etag.clone()?, base(&e.source_hash))))
                .collect(),
        }
    }
}

/// Converts one input of a job: returns its content hash (empty when it could not be taken)
/// and its episodes, or why there are none.
pub(crate) fn convert_input(
    input: &Input,
    opts: &JobOptions,
    existing: &Existing,
) -> (String, Episodes) {
    let skipped = |h: String| {
        (
            h,
            Err(InputResult::Skipped("already in the dataset".into())),
        )
    };
    let path = match input {
        Input::Local(path) => path,
        Input::Object(o) => {
            let known = input.version().and_then(|v| existing.versions.get(&v));
            if let Some(h) = known.filter(|h| fully_converted(&existing.hashes, h)) {
                return skipped(h.clone());
            }
            return match guarded(&o.url.as_path(), || convert_object(o, opts)) {
                (_, Some(h)) if fully_converted(&existing.hashes, &h) => skipped(h),
                (r, h) => (h.unwrap_or_default(), r),
            };
        }
    };
    match existing.hashes.is_empty() && is_mcap_file(path) {
        // Nothing to skip: hash the file during its one read.
        true => match convert_guarded(path, opts, true) {
            (r, Some(h)) => (h, r),
            (r, None) => (content_hash(path).unwrap_or_default(), r),
        },
        false => match content_hash(path) {
            Err(e) => (String::new(), Err(InputResult::Failed(e))),
            Ok(h) if fully_converted(&existing.hashes, &h) => skipped(h),
            Ok(h) => (h, convert_guarded(path, opts, false).0),
        },
    }
}

/// [`convert_one`], a panic (a bug, never bad input) becoming a failure of this input alone
/// instead of the end of the batch.
fn convert_guarded(path: &Path, opts: &JobOptions, hash: bool) -> (Episodes, Option<String>) {
    guarded(path, || convert_one(path, opts, hash))
}

/// Runs `f`; a panic becomes a failed outcome naming `path` (and no hash).
fn guarded(
    path: &Path,
    f: impl FnOnce() -> (Episodes, Option<String>),
) -> (Episodes, Option<String>) {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).unwrap_or_else(|panic| {
        let message = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into());
        let line = Error::input(path, format!("internal error while converting: {message}"));
        (Err(InputResult::Failed(line)), None)
    })
}

/// Skips episodes the operator marked as discarded or failed, and unlabelled ones as the job
/// says ([`Unlabeled`]).
fn check_outcome(
    path: &Path,
    rec: &Recording,
    opts: &JobOptions,
) -> std::result::Result<(), InputResult> {
    let meta = crate::detect::episode_metadata(path, rec).map_err(InputResult::Failed)?;
    match crate::recorded::label_of(meta.as_ref()) {
        Label::Discarded => return Err(InputResult::Skipped("recorded outcome: discarded".into())),
        Label::Failure if !opts.include_failures => {
            return Err(InputResult::Skipped(
                "recorded outcome: failure (see --include-failures)".into(),
            ))
        }
        Label::Unlabeled => match opts.unlabeled {
            Unlabeled::Keep => {}
            Unlabeled::Skip => {
                return Err(InputResult::Skipped("unlabelled (--unlabeled skip)".into()))
            }
            Unlabeled::Refuse => {
                return Err(InputResult::Failed(Error::Rejected {
                    path: path.into(),
                    reason: "unlabelled (recorded without a success or failure label): choose \
                             --unlabeled keep or --unlabeled skip"
                        .into(),
                }))
            }
        },
        _ => {}
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn failure(r: Episodes) -> String {
        match r {
            Err(InputResult::Failed(e)) => e.to_string(),
            Err(other) => format!("not a failure: {other:?}"),
            Ok(_) => "converted".into(),
        }
    }

    #[test]
    fn a_panic_fails_that_input_alone() {
        let path = Path::new("/data/ep7.mcap");
        let (r, hash) = guarded(path, || panic!("index out of bounds: {}", 3));
        let line = failure(r);
        assert!(line.starts_with("/data/ep7.mcap: "), "{line}");
        assert!(
            line.ends_with("internal error while converting: index out of bounds: 3"),
            "{line}"
        );
        assert!(hash.is_none());
        let (r, _) = guarded(path, || panic!("boom"));
        assert!(failure(r).ends_with("converting: boom"));
        // Without a panic, the result passes through.
        let (r, hash) = guarded(path, || (Ok(Vec::new()), Some("h".into())));
        assert!(r.is_ok_and(|e| e.is_empty()));
        assert_eq!(hash.as_deref(), Some("h"));
    }
}
