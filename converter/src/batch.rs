//! The batch job: many inputs → one dataset, converted in parallel, committed in input order,
//! one failure never stopping the rest.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc;

use rayon::prelude::*;
use scaledp_schema::Label;

use crate::episode::{convert, Episode};
use crate::error::{Error, Result};
use crate::frames::FrameStore;
use crate::inputs::{
    content_hash, hasher_for, input_bytes, is_mcap_file, read_input, shard, useful_topic,
};
use crate::lerobot::{Dataset, EpisodeRecord};
use crate::options::{ConvertOptions, JobOptions};
use crate::source::Recording;

/// What happened to one input of a [`run`].
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

/// Progress events of a [`run`], for a front end.
#[derive(Debug)]
pub enum Progress<'a> {
    /// The number of inputs in this job (after sharding).
    Total(usize),
    /// One input is done.
    Done {
        /// The input.
        input: &'a Path,
        /// What happened.
        result: &'a InputResult,
        /// Frames in the episode (0 unless converted).
        frames: usize,
        /// Bytes of the input.
        bytes: u64,
    },
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
type Episodes = std::result::Result<Vec<Episode>, InputResult>;

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

/// Converts one input; for an MCAP file with `hash`, also returns its [`content_hash`], taken
/// during the one read (no second pass over the file).
fn convert_one(path: &Path, opts: &JobOptions, hash: bool) -> (Episodes, Option<String>) {
    let failed = InputResult::Failed;
    let run = |rec: &Recording, frames: &dyn FrameStore| -> Episodes {
        check_outcome(path, rec, opts)?;
        let parts = windows(rec, frames, opts.split_gap_s);
        let split = parts.len() > 1;
        let mut episodes = Vec::with_capacity(parts.len());
        for (k, window) in parts.into_iter().enumerate() {
            let copts = ConvertOptions {
                window_ns: window,
                ..opts.convert.clone()
            };
            let mut ep = convert(path, rec, frames, &copts).map_err(failed)?;
            if split {
                let mut name = ep.source.into_os_string();
                name.push(format!("#{k}"));
                ep.source = name.into();
            }
            episodes.push(ep);
        }
        Ok(episodes)
    };
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
        .and_then(|rec| run(&rec, &crate::frames::InMemory(&rec)));
    (converted, None)
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

/// Skips episodes the operator marked as discarded or failed.
fn check_outcome(
    path: &Path,
    rec: &Recording,
    opts: &JobOptions,
) -> std::result::Result<(), InputResult> {
    let label = crate::detect::episode_metadata(path, rec)
        .map_err(InputResult::Failed)?
        .and_then(|m| m.label);
    match label {
        Some(Label::Discarded) => {
            return Err(InputResult::Skipped("recorded outcome: discarded".into()))
        }
        Some(Label::Failure) if !opts.include_failures => {
            return Err(InputResult::Skipped(
                "recorded outcome: failure (see --include-failures)".into(),
            ))
        }
        _ => {}
    }
    Ok(())
}

/// Converts `inputs` into the dataset at `out`. Inputs already present (by content hash) are
/// skipped. Episodes are committed in input order whatever order they finish in; a failure is
/// reported and the rest go on. Returns one outcome per input, in input order.
pub fn run(
    inputs: &[PathBuf],
    out: &Path,
    opts: &JobOptions,
    progress: &(dyn Fn(Progress<'_>) + Sync),
) -> Result<Vec<(PathBuf, InputResult)>> {
    let inputs = match opts.shard {
        Some((i, n)) if n > 0 && i < n => shard(inputs, i, n).to_vec(),
        Some((i, n)) => {
            return Err(Error::input(
                out,
                format!("bad shard {i}/{n}: need 0 ≤ I < N"),
            ))
        }
        None => inputs.to_vec(),
    };
    let mut dataset = Dataset::open(out, opts.overwrite, opts.file_size_mib)?;
    progress(Progress::Total(inputs.len()));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.jobs.max(1))
        .build()
        .map_err(|e| Error::input(out, format!("thread pool: {e}")))?;
    let (tx, rx) = mpsc::channel::<(usize, String, Episodes)>();
    let mut results: BTreeMap<usize, (PathBuf, InputResult)> = BTreeMap::new();
    std::thread::scope(|scope| -> Result<()> {
        let inputs_ref = &inputs;
        let existing: Vec<String> = dataset
            .episodes()
            .iter()
            .map(|e| e.source_hash.clone())
            .collect();
        scope.spawn(move || {
            pool.install(|| {
                inputs_ref
                    .par_iter()
                    .enumerate()
                    .for_each_with(tx, |tx, (i, path)| {
                        let (hash, r) = match existing.is_empty() && is_mcap_file(path) {
                            // Nothing to skip: hash the file during its one read.
                            true => match convert_guarded(path, opts, true) {
                                (r, Some(h)) => (h, r),
                                (r, None) => (content_hash(path).unwrap_or_default(), r),
                            },
                            false => match content_hash(path) {
                                Err(e) => (String::new(), Err(InputResult::Failed(e))),
                                Ok(h) if fully_converted(&existing, &h) => {
                                    let why = "already in the dataset".to_string();
                                    (h, Err(InputResult::Skipped(why)))
                                }
                                Ok(h) => (h, convert_guarded(path, opts, false).0),
                            },
                        };
                        let _ = tx.send((i, hash, r));
                    });
            })
        });
        // Commit in input order: hold finished episodes until all before them are done.
        let mut pending: BTreeMap<usize, (String, Episodes)> = BTreeMap::new();
        let mut next = 0;
        for (i, hash, r) in rx {
            pending.insert(i, (hash, r));
            while let Some((hash, r)) = pending.remove(&next) {
                let path = inputs[next].clone();
                let (outcome, frames) = match r {
                    Ok(episodes) => {
                        let n = episodes.len();
                        let mut records = Vec::with_capacity(n);
                        let mut frames = 0;
                        let mut failure = None;
                        for (k, ep) in episodes.iter().enumerate() {
                            let part_hash = if n > 1 {
                                format!("{hash}#{k}/{n}")
                            } else {
                                hash.clone()
                            };
                            if dataset.contains(&part_hash) {
                                continue; // committed before an interrupted run stopped
                            }
                            match dataset.add(ep, &part_hash) {
                                Ok(rec) => {
                                    frames += ep.len();
                                    records.push(rec);
                                }
                                Err(e @ Error::Rejected { .. }) => {
                                    failure = Some(e);
                                    break;
                                }
                                Err(e) => return Err(e),
                            }
                        }
                        match failure {
                            Some(e) => (InputResult::Failed(e), frames),
                            None => (InputResult::Converted(records), frames),
                        }
                    }
                    Err(o) => (o, 0),
                };
                progress(Progress::Done {
                    input: &path,
                    result: &outcome,
                    frames,
                    bytes: input_bytes(&path),
                });
                results.insert(next, (path, outcome));
                next += 1;
            }
        }
        Ok(())
    })?;
    Ok(results.into_values().collect())
}

/// Joins scaledp datasets (e.g. the outputs of `--shard 0/N … N-1/N`) into `out`, in the order
/// given, re-indexing episodes, frames and tasks and re-aggregating statistics; data files of
/// `file_size_mib` MiB. Returns the number of episodes.
pub fn merge(inputs: &[PathBuf], out: &Path, file_size_mib: u64) -> Result<usize> {
    let mut dataset = Dataset::open(out, true, file_size_mib)?;
    let mut n = 0;
    for input in inputs {
        let record = input.join("meta/scaledp.json");
        let text = std::fs::read(&record).map_err(Error::io(&record))?;
        let sidecar: crate::lerobot::Sidecar = serde_json::from_slice(&text)
            .map_err(|e| Error::input(&record, format!("unreadable: {e}")))?;
        for ep in &sidecar.episodes {
            dataset.add_from(input, &sidecar, ep)?;
            n += 1;
        }
    }
    Ok(n)
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
