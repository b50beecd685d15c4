//! Recorder-style episodes written straight to MCAP by the simulator, several at a time: the
//! input of `bench convert` and the raw material of `bench load`'s dataset.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use anyhow::{bail, Result};
use scaledp_schema::Rig;

/// Start of episode 0 (ns); episode `i` starts `i` minutes later.
const T0_NS: u64 = 1_700_000_000_000_000_000;

/// Writes episodes `ids` (seed = id) of `rig` as `episode_NNNNNN.mcap` files into `dir`, `jobs`
/// at a time; returns their paths.
pub fn synthesize(
    dir: &Path,
    rig: &Rig,
    ids: &[usize],
    seconds: f64,
    task: &str,
    jobs: usize,
) -> Result<Vec<PathBuf>> {
    let paths: Vec<PathBuf> = ids
        .iter()
        .map(|i| dir.join(format!("episode_{i:06}.mcap")))
        .collect();
    let next = AtomicUsize::new(0);
    let errors = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..jobs.min(ids.len()) {
            s.spawn(|| loop {
                let k = next.fetch_add(1, Ordering::Relaxed);
                let (Some(&i), Some(path)) = (ids.get(k), paths.get(k)) else {
                    break;
                };
                // Distinct start times, a minute apart.
                let start_ns = T0_NS + i as u64 * 60_000_000_000;
                let r = scaledp_sim::synth::write_episode(
                    path,
                    rig,
                    i as u64,
                    seconds,
                    start_ns,
                    task,
                    &mut |_, _, _, _| {},
                );
                if let Err(e) = r {
                    errors
                        .lock()
                        .unwrap_or_else(|p| p.into_inner())
                        .push(format!("{}: {e:#}", path.display()));
                }
            });
        }
    });
    let errors = errors.into_inner().unwrap_or_else(|p| p.into_inner());
    if !errors.is_empty() {
        bail!("generating the recordings failed: {}", errors.join("; "));
    }
    Ok(paths)
}
