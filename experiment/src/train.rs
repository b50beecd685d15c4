//! Training one arm: a new run, or the resumption of an interrupted one, to the recipe's step
//! count, with a progress bar; Ctrl-C (or SIGTERM) checkpoints and stops, and the next
//! `experiment compare` continues from there.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{Context, Result};
use candle_core::Device;
use indicatif::{ProgressBar, ProgressStyle};
use scaledp_policy::{Event, TrainOptions, Trainer};

/// What a finished (or stopped) training left.
#[derive(Debug, Clone, Copy)]
pub struct Trained {
    /// Steps done.
    pub steps: u64,
    /// Σ of the steps' wall times (h), over every session of the run.
    pub hours: f64,
    /// Stopped before the last step (Ctrl-C).
    pub interrupted: bool,
}

/// Trains (or resumes) the run in `run` on `dataset` with `opts` until `opts`' step count.
pub fn train(
    dataset: &str,
    run: &Path,
    opts: TrainOptions,
    stop: &Arc<AtomicBool>,
) -> Result<Trained> {
    let total = opts.get_steps();
    let existing = scaledp_policy::list_checkpoints(run)?;
    let mut trainer = match existing.last() {
        Some((step, _)) if *step >= total => {
            return Ok(Trained {
                steps: *step,
                hours: train_hours(run)?,
                interrupted: false,
            })
        }
        Some(_) => Trainer::resume(run, Some(total), &Device::Cpu)?,
        None => Trainer::new(dataset, run, opts, &Device::Cpu)?,
    };
    let flag = trainer.stop_flag();
    let bar = ProgressBar::new(total).with_position(trainer.step_count());
    bar.set_style(
        ProgressStyle::with_template(
            "  {bar:30} {pos}/{len} steps {msg} [{elapsed_precise} < {eta_precise}]",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let summary = trainer.run(|e| {
        if stop.load(Ordering::Relaxed) {
            flag.store(true, Ordering::Relaxed);
        }
        if let Event::Step(r) = e {
            bar.set_position(r.step);
            bar.set_message(format!("loss {:.4}, {:.2} s/step", r.loss, r.step_s));
        }
    })?;
    bar.finish_and_clear();
    Ok(Trained {
        steps: summary.steps,
        hours: train_hours(run)?,
        interrupted: summary.interrupted,
    })
}

/// Σ of `step_s` over the run's `metrics.jsonl` training records (h), and their mean (s).
pub fn train_hours(run: &Path) -> Result<f64> {
    Ok(step_times(run)?.iter().sum::<f64>() / 3600.0)
}

/// The wall time of every step in `metrics.jsonl` (s).
pub fn step_times(run: &Path) -> Result<Vec<f64>> {
    let path = run.join("metrics.jsonl");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    Ok(text
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["kind"] == "train")
        .filter_map(|v| v["record"]["step_s"].as_f64())
        .collect())
}
