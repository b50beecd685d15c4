//! `scaledp experiment grad-scale`: the measurement behind the paper's explanation of why DP-T
//! stops improving with depth. DP-T and ScaleDP are trained at the same depths (8, 12, 14 by
//! default), width and heads, on the same dataset, batches, encoders and seeds, for a fixed
//! number of steps; at every step each block's gradient norm is recorded and their spread
//! across the blocks reported.
//!
//! The measure, stated exactly: at step k, G_i = the L2 norm of the gradient of every parameter
//! of block i (ScaleDP: `blocks.i.*`; DP-T: `model.decoder.layers.i.*`), before clipping and
//! the update. The spread is the standard deviation of {G_i} across the blocks (population),
//! and the same divided by their mean (the coefficient of variation: scale-free, so two
//! architectures whose gradients differ in overall size can be compared). The summary of a
//! model is each spread's mean over the second half of the steps (past the warm-up) and its
//! value at the last step.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{anyhow, bail, Context, Result};
use candle_core::Device;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use plotters::prelude::*;
use scaledp_policy::{Architecture, Attention, TrainOptions, Trainer, DPT_DIMS};
use serde::{Deserialize, Serialize};

use crate::provenance::Provenance;

/// `scaledp experiment grad-scale`.
#[derive(Debug, Clone, Args)]
pub struct GradScaleArgs {
    /// The dataset (small is enough: the measurement is of the gradients, not of success).
    #[arg(long)]
    pub dataset: String,
    /// Depths of both architectures, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "8,12,14")]
    pub depths: Vec<usize>,
    /// Optimizer steps per model.
    #[arg(long, default_value_t = 300)]
    pub steps: u64,
    /// Samples per step.
    #[arg(long, default_value_t = 32)]
    pub batch_size: usize,
    /// Images resized to WxH before the crop.
    #[arg(long, value_name = "WxH", default_value = "64x64")]
    pub image_size: String,
    /// Seed of the weights, data order, crops, noise and dropout (every model the same).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Where the runs go (never committed).
    #[arg(long, default_value = "runs/experiments/grad-scale")]
    pub runs: PathBuf,
    /// Where the results go.
    #[arg(long, default_value = "docs/results/grad-scale")]
    pub results: PathBuf,
}

/// One step's figures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GradStep {
    /// Steps done.
    pub step: u64,
    /// The batch's loss.
    pub loss: f32,
    /// G_i per block, first block first.
    pub block_norms: Vec<f64>,
    /// Standard deviation of the block norms.
    pub std: f64,
    /// That over their mean.
    pub cv: f64,
}

/// One model's measurement: `RESULTS/<model>.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GradRun {
    /// `dp-t-l8`, `scaledp-l12`, …
    pub model: String,
    /// `scale_dp` or `dp_t`.
    pub arch: String,
    /// Blocks.
    pub depth: usize,
    /// Width.
    pub width: usize,
    /// Heads.
    pub heads: usize,
    /// Every step.
    pub steps: Vec<GradStep>,
    /// Mean of the standard deviation over the second half of the steps.
    pub std_second_half: f64,
    /// Mean of the coefficient of variation over the second half of the steps.
    pub cv_second_half: f64,
    /// The training settings.
    pub train_options: serde_json::Value,
    /// The command.
    pub command: String,
    /// Where and what ran.
    pub provenance: Provenance,
}

/// Which block a parameter belongs to.
fn block_of(name: &str) -> Option<usize> {
    let rest = name
        .strip_prefix("blocks.")
        .or_else(|| name.strip_prefix("model.decoder.layers."))?;
    rest.split('.').next()?.parse().ok()
}

fn spread(norms: &[f64]) -> (f64, f64) {
    let n = norms.len().max(1) as f64;
    let mean = norms.iter().sum::<f64>() / n;
    let var = norms.iter().map(|g| (g - mean).powi(2)).sum::<f64>() / n;
    (var.sqrt(), if mean > 0.0 { var.sqrt() / mean } else { 0.0 })
}

fn parse_size(s: &str) -> Result<(u32, u32)> {
    let (w, h) = s.split_once('x').context("--image-size WxH")?;
    Ok((w.parse()?, h.parse()?))
}

/// Runs the measurement; `stop` ends it early (results so far are kept per model).
pub fn run(a: &GradScaleArgs, stop: &Arc<AtomicBool>) -> Result<()> {
    if a.depths.is_empty() || a.steps < 2 {
        bail!("--depths needs at least one depth and --steps at least 2");
    }
    std::fs::create_dir_all(&a.results)
        .with_context(|| format!("creating {}", a.results.display()))?;
    let (w, h) = parse_size(&a.image_size)?;
    let (_, width, heads) = DPT_DIMS;
    for arch in [Architecture::DpT, Architecture::ScaleDp] {
        for &depth in &a.depths {
            let model = format!("{}-l{depth}", arch.name());
            let path = a.results.join(format!("{model}.json"));
            if path.exists() {
                continue;
            }
            // The cube recipe's encoders and loss, a short cosine schedule, every model alike;
            // each architecture with the paper's attention (ScaleDP non-causal, DP-T its masks),
            // not `scaledp train`'s causal default.
            let attention = match arch {
                Architecture::ScaleDp => Attention::NonCausal,
                Architecture::DpT => Attention::Causal,
            };
            let opts = TrainOptions::preset("cpu-sim")
                .context("the cpu-sim preset")?
                .arch(arch)
                .attention(attention)
                .denoiser(depth, width, heads)
                .steps(a.steps)
                .warmup_steps(a.steps / 6)
                .batch_size(a.batch_size)
                .image_size(w, h)
                .seed(a.seed)
                .checkpoint_every(0);
            let run_dir = a.runs.join(&model);
            let _ = std::fs::remove_dir_all(&run_dir);
            let mut trainer = Trainer::new(&a.dataset, &run_dir, opts.clone(), &Device::Cpu)?;
            let bar = ProgressBar::new(a.steps).with_style(
                ProgressStyle::with_template(
                    "  {msg} {bar:30} {pos}/{len} steps [{elapsed_precise}]",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            bar.set_message(model.clone());
            let mut steps = Vec::new();
            while trainer.step_count() < a.steps {
                if stop.load(Ordering::Relaxed) {
                    bar.finish_and_clear();
                    eprintln!("stopped: {model} is measured again from the start next time");
                    return Ok(());
                }
                let mut sq: BTreeMap<usize, f64> = BTreeMap::new();
                let rec = trainer.step_inspect(&mut |name, g| {
                    if let Some(b) = block_of(name) {
                        let s = g
                            .sqr()
                            .and_then(|x| x.sum_all())
                            .and_then(|x| x.to_scalar::<f32>())
                            .map_or(f64::NAN, f64::from);
                        *sq.entry(b).or_default() += s;
                    }
                })?;
                let norms: Vec<f64> = sq.values().map(|s| s.sqrt()).collect();
                if norms.len() != depth {
                    bail!("{model}: gradients of {} blocks, not {depth}", norms.len());
                }
                let (std, cv) = spread(&norms);
                steps.push(GradStep {
                    step: rec.step,
                    loss: rec.loss,
                    block_norms: norms,
                    std,
                    cv,
                });
                bar.set_position(rec.step);
            }
            bar.finish_and_clear();
            let half = &steps[steps.len() / 2..];
            let mean =
                |f: fn(&GradStep) -> f64| half.iter().map(f).sum::<f64>() / half.len() as f64;
            let r = GradRun {
                model: model.clone(),
                arch: match arch {
                    Architecture::ScaleDp => "scale_dp".into(),
                    Architecture::DpT => "dp_t".into(),
                },
                depth,
                width,
                heads,
                std_second_half: mean(|s| s.std),
                cv_second_half: mean(|s| s.cv),
                steps,
                train_options: serde_json::to_value(&opts)?,
                command: format!(
                    "scaledp experiment grad-scale --dataset {} --depths {} --steps {} --batch-size {} --image-size {} --seed {}",
                    a.dataset,
                    a.depths.iter().map(usize::to_string).collect::<Vec<_>>().join(","),
                    a.steps,
                    a.batch_size,
                    a.image_size,
                    a.seed
                ),
                provenance: Provenance::now(),
            };
            std::fs::write(&path, serde_json::to_vec_pretty(&r)?)
                .with_context(|| format!("writing {}", path.display()))?;
            eprintln!(
                "{model}: spread of block gradient norms over the second half: std {:.3e}, std/mean {:.3}",
                r.std_second_half, r.cv_second_half
            );
            let _ = std::fs::remove_dir_all(&run_dir);
        }
    }
    report(&a.results)
}

/// Rebuilds `table.md` and `spread.svg` from the model files in `dir`.
pub fn report(dir: &Path) -> Result<()> {
    let mut runs: Vec<GradRun> = Vec::new();
    for e in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let p = e?.path();
        if p.extension().is_some_and(|x| x == "json") {
            let bytes = std::fs::read(&p)?;
            runs.push(serde_json::from_slice(&bytes).with_context(|| format!("{}", p.display()))?);
        }
    }
    runs.sort_by(|a, b| (&a.arch, a.depth).cmp(&(&b.arch, b.depth)));
    if runs.is_empty() {
        bail!("{}: no measurements", dir.display());
    }
    let mut md = String::from(
        "# Spread of gradient norms across blocks\n\nG_i = L2 norm of block i's gradient at each \
         step (before clipping and the update); spread = standard deviation of {G_i} across the \
         blocks, and that over their mean (scale-free). Summary = mean over the second half of \
         the steps. Rebuilt by `scaledp experiment grad-scale` from the files beside it.\n\n\
         | model | depth | std (2nd half) | std / mean (2nd half) | std / mean (last step) | last loss |\n|---|---|---|---|---|---|\n",
    );
    for r in &runs {
        let last = r.steps.last();
        md.push_str(&format!(
            "| {} | {} | {:.3e} | {:.3} | {:.3} | {:.4} |\n",
            r.model,
            r.depth,
            r.std_second_half,
            r.cv_second_half,
            last.map_or(f64::NAN, |s| s.cv),
            last.map_or(f32::NAN, |s| s.loss)
        ));
    }
    if let Some(r) = runs.first() {
        md.push_str(&format!(
            "\nCommand: `{}` — revision `{}`, {}, {}.\n",
            r.command, r.provenance.git_revision, r.provenance.machine, r.provenance.finished_utc
        ));
    }
    std::fs::write(dir.join("table.md"), md)?;
    plot(&runs, &dir.join("spread.svg"))
}

fn plot(runs: &[GradRun], path: &Path) -> Result<()> {
    let err = |e: String| anyhow!("plot: {e}");
    let max_step = runs
        .iter()
        .flat_map(|r| r.steps.last().map(|s| s.step))
        .max()
        .unwrap_or(1);
    // A moving average over 20 steps: single steps' norms are noisy.
    let smooth = |r: &GradRun| -> Vec<(u64, f64)> {
        r.steps
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let w = &r.steps[i.saturating_sub(19)..=i];
                (s.step, w.iter().map(|x| x.cv).sum::<f64>() / w.len() as f64)
            })
            .collect()
    };
    let top = runs
        .iter()
        .flat_map(|r| smooth(r).into_iter().map(|p| p.1))
        .fold(0.1, f64::max);
    let root = SVGBackend::new(path, (800, 460)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "spread of block gradient norms (std / mean, 20-step mean)",
            ("sans-serif", 20),
        )
        .margin(16)
        .x_label_area_size(40)
        .y_label_area_size(56)
        .build_cartesian_2d(0u64..max_step, 0f64..top * 1.05)
        .map_err(|e| err(e.to_string()))?;
    chart
        .configure_mesh()
        .x_desc("optimizer step")
        .y_desc("std / mean of the blocks' gradient norms")
        .draw()
        .map_err(|e| err(e.to_string()))?;
    for r in runs {
        let shade = (r.depth as f64 - 6.0) / 10.0;
        let c = if r.arch == "dp_t" {
            RGBColor(214, (140.0 * (1.0 - shade)) as u8, 40)
        } else {
            RGBColor(31, (160.0 * (1.0 - shade)) as u8, 180)
        };
        chart
            .draw_series(LineSeries::new(smooth(r), c.stroke_width(2)))
            .map_err(|e| err(e.to_string()))?
            .label(format!("{} ({:.2})", r.model, r.cv_second_half))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| err(e.to_string()))?;
    root.present().map_err(|e| err(e.to_string()))?;
    Ok(())
}
