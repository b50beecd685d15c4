//! The batch job: many inputs → one dataset, converted in parallel, committed in input order,
//! one failure never stopping the rest. Inputs and the dataset may be local or in object
//! storage (see [`crate::destination`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc;

use rayon::prelude::*;
use scaledp_store::Location;

use crate::destination::Destination;
use crate::error::{Error, Result};
use crate::inputs::shard;
use crate::objects::Input;
use crate::options::{JobOptions, Unlabeled};
pub use crate::per_input::InputResult;
use crate::per_input::{convert_input, Episodes, Existing};

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

/// Converts `inputs` into the dataset at `out`. Inputs already present (by content hash) are
/// skipped. Episodes are committed in input order whatever order they finish in; a failure is
/// reported and the rest go on. Returns one outcome per input, in input order.
pub fn run(
    inputs: &[PathBuf],
    out: &Path,
    opts: &JobOptions,
    progress: &(dyn Fn(Progress<'_>) + Sync),
) -> Result<Vec<(PathBuf, InputResult)>> {
    let inputs: Vec<Input> = inputs.iter().cloned().map(Input::Local).collect();
    run_inputs(&inputs, &Location::Local(out.into()), opts, progress)
}

/// [`run`] for inputs and a dataset anywhere: local paths or object storage (see
/// [`crate::collect`] and [`crate::destination`]). Results name inputs by path or URL.
pub fn run_inputs(
    inputs: &[Input],
    out: &Location,
    opts: &JobOptions,
    progress: &(dyn Fn(Progress<'_>) + Sync),
) -> Result<Vec<(PathBuf, InputResult)>> {
    let inputs = match opts.shard {
        Some((i, n)) if n > 0 && i < n => shard(inputs, i, n).to_vec(),
        Some((i, n)) => {
            return Err(Error::input(
                out.as_path(),
                format!("bad shard {i}/{n}: need 0 ≤ I < N"),
            ))
        }
        None => inputs.to_vec(),
    };
    if opts.unlabeled == Unlabeled::Refuse {
        let unlabeled = crate::labels::unlabeled_inputs(&inputs);
        if !unlabeled.is_empty() {
            let line = crate::labels::refusal(&unlabeled);
            return Err(Error::Unlabeled {
                inputs: unlabeled,
                line,
            });
        }
    }
    if let (Location::Object(_), Some(_)) = (out, opts.convert.video) {
        return Err(Error::input(
            out.as_path(),
            "video features (--video) are written to local datasets only for now; convert \
             to a local directory and upload it",
        ));
    }
    let mut dest = Destination::open(
        out,
        opts.overwrite,
        opts.file_size_mib,
        &opts.work_dir_or_temp(),
    )?;
    progress(Progress::Total(inputs.len()));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.jobs.max(1))
        .build()
        .map_err(|e| Error::input(out.as_path(), format!("thread pool: {e}")))?;
    let (tx, rx) = mpsc::channel::<(usize, String, Episodes)>();
    let mut results: BTreeMap<usize, (PathBuf, InputResult)> = BTreeMap::new();
    std::thread::scope(|scope| -> Result<()> {
        let inputs_ref = &inputs;
        let existing = Existing::of(dest.dataset().episodes());
        scope.spawn(move || {
            pool.install(|| {
                inputs_ref
                    .par_iter()
                    .enumerate()
                    .for_each_with(tx, |tx, (i, input)| {
                        let (hash, r) = convert_input(input, opts, &existing);
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
                let input = &inputs[next];
                let path = input.name();
                let dataset = dest.dataset();
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
                            match dataset.add(ep, &part_hash, input.version()) {
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
                dest.committed()?;
                progress(Progress::Done {
                    input: &path,
                    result: &outcome,
                    frames,
                    bytes: input.bytes(),
                });
                results.insert(next, (path, outcome));
                next += 1;
            }
        }
        Ok(())
    })?;
    dest.finish()?;
    Ok(results.into_values().collect())
}
