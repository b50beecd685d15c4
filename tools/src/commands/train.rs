//! `scaledp train`: a ScaleDP policy on a LeRobot dataset (the `scaledp-policy` trainer), with a
//! progress bar on stderr; every step's figures go to `<out>/metrics.jsonl`.

use std::path::PathBuf;
use std::sync::atomic::Ordering;

use anyhow::{bail, Context, Result};
use clap::Args;
use scaledp_policy::model::ScaleDp;
use scaledp_policy::{Architecture, Event, ModelConfig, StateNorm, TrainOptions, Trainer};

use crate::cli::ExitStatus;
use crate::shared;

/// `scaledp train`. Every setting left out takes the preset's value (`--preset`), else the
/// default shown in brackets: the paper's / diffusion_policy's, except ScaleDP's attention,
/// which is causal (`--preset paper` is the paper's configuration whole).
#[derive(Debug, Args)]
pub struct TrainArgs {
    /// The dataset: a directory or s3://bucket/prefix (not needed with --resume, or with
    /// --dry-run for the paper's setup).
    pub dataset: Option<String>,
    /// A named recipe to start from (cpu-sim: ScaleDP-Ti on the simulated cube task within
    /// three hours on two CPU cores; cpu-metaworld, cpu-aloha: the benchmarks'; paper: the
    /// paper's ScaleDP, non-causal); the flags below override it one by one.
    #[arg(long)]
    pub preset: Option<String>,
    /// Model: a ScaleDP size (ti, s, b, l or h) or dp-t, the paper's baseline
    /// (diffusion_policy's transformer: 8 layers, width 256, 4 heads, causal masks, dropout
    /// 0.3) [ti].
    #[arg(long)]
    pub model: Option<String>,
    /// Denoiser depth instead of the model's (the DP-T depth ablation: 8, 12, 14).
    #[arg(long)]
    pub layers: Option<usize>,
    /// Denoiser width instead of the model's.
    #[arg(long)]
    pub width: Option<usize>,
    /// Attention heads instead of the model's.
    #[arg(long)]
    pub heads: Option<usize>,
    /// Dropout while training [DP-T 0.3; ScaleDP none].
    #[arg(long)]
    pub dropout: Option<f64>,
    /// Run directory (metrics.jsonl, checkpoints/step_*).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Continue the run in this directory from its latest checkpoint.
    #[arg(long, value_name = "DIR", conflicts_with = "out")]
    pub resume: Option<PathBuf>,
    /// Optimizer steps in total [10000].
    #[arg(long)]
    pub steps: Option<u64>,
    /// Samples per step [64].
    #[arg(long)]
    pub batch_size: Option<usize>,
    /// Forward/backward at most this many samples at a time (same update, less memory).
    #[arg(long)]
    pub micro_batch: Option<usize>,
    /// Peak learning rate, cosine schedule after the warm-up [1e-4].
    #[arg(long)]
    pub lr: Option<f64>,
    /// Warm-up steps [500].
    #[arg(long)]
    pub warmup_steps: Option<u64>,
    /// Seed of the weights, data order, crops and noise [0].
    #[arg(long)]
    pub seed: Option<u64>,
    /// cpu, or cuda (a build with the `cuda` feature of scaledp-policy).
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// Checkpoint every N steps, and at the start (the untrained weights) and the end [1000].
    #[arg(long)]
    pub checkpoint_every: Option<u64>,
    /// Validate every N steps, 0: never [1000].
    #[arg(long)]
    pub val_every: Option<u64>,
    /// Fraction of episodes held out for validation [0.05].
    #[arg(long)]
    pub val_ratio: Option<f64>,
    /// Clip the global gradient norm [no clipping].
    #[arg(long)]
    pub grad_clip: Option<f64>,
    /// Crop side / image side, random in training, centred in inference [0.9].
    #[arg(long)]
    pub crop: Option<f64>,
    /// Observation frames per sample, To [2].
    #[arg(long)]
    pub obs_horizon: Option<usize>,
    /// Actions per chunk, C [16].
    #[arg(long)]
    pub action_chunk: Option<usize>,
    /// Resize images to WxH before the crop (e.g. 84x84) [as stored].
    #[arg(long, value_name = "WxH")]
    pub image_size: Option<String>,
    /// Cameras to use, comma-separated short names [all].
    #[arg(long, value_delimiter = ',')]
    pub cameras: Vec<String>,
    /// Channels of the ResNet-18 trunks' first stage; 32 or 16 cost 4 or 16 times less [64].
    #[arg(long)]
    pub resnet_width: Option<usize>,
    /// (timestep, noise) draws per encoded observation: the encoders run once per sample and
    /// the denoiser this many times [1].
    #[arg(long)]
    pub noise_samples: Option<usize>,
    /// The denoiser's attention over the action chunk: non-causal (the paper's ScaleDP) or
    /// causal, above the paper's on ALOHA's two tasks and below it on none measured (README,
    /// Train) [causal; DP-T: its own masks].
    #[arg(long)]
    pub attention: Option<String>,
    /// ScaleDP's positional embedding of the action tokens: learned (the paper's, from
    /// N(0, 0.02)), sin-cos (DiT's fixed table, not trained) or learned-sin-cos (trained,
    /// starting from DiT's table) [learned].
    #[arg(long)]
    pub pos_embed: Option<String>,
    /// Leave action steps past an episode's end out of the loss (by default they are trained
    /// on, as diffusion_policy and LeRobot do: they repeat the last action).
    #[arg(long)]
    pub mask_padding: bool,
    /// The state's normalization: min-max ([-1, 1], diffusion_policy's and LeRobot's) or
    /// mean-std [min-max].
    #[arg(long)]
    pub state_norm: Option<String>,
    /// Weight decay of the denoiser's Linear weights, diffusion_policy's
    /// transformer_weight_decay [1e-3].
    #[arg(long)]
    pub weight_decay: Option<f64>,
    /// Weight decay of every encoder parameter, diffusion_policy's obs_encoder_weight_decay
    /// [1e-6].
    #[arg(long)]
    pub encoder_weight_decay: Option<f64>,
    /// Print the parameter counts and stop.
    #[arg(long)]
    pub dry_run: bool,
    /// Plot the loss, learning rate and validation errors in a rerun viewer: a new one, or the
    /// one at URL (e.g. rerun+http://host:9876/proxy).
    #[arg(long, value_name = "URL", num_args = 0..=1)]
    pub view: Option<Option<String>>,
}

fn size(s: &str) -> Result<(u32, u32)> {
    let (w, h) = s
        .split_once('x')
        .context("--image-size takes WxH, e.g. 84x84")?;
    Ok((w.parse()?, h.parse()?))
}

/// The run's options: the preset (or the defaults), then every flag given.
pub fn options(a: &TrainArgs) -> Result<TrainOptions> {
    let mut o = match &a.preset {
        Some(p) => TrainOptions::preset(p).with_context(|| {
            format!(
                "--preset {p}: one of {}",
                scaledp_policy::PRESETS.join(", ")
            )
        })?,
        None => TrainOptions::default(),
    };
    if let Some(m) = &a.model {
        o = match m.parse::<Architecture>() {
            Ok(Architecture::DpT) => o.arch(Architecture::DpT),
            _ => o.arch(Architecture::ScaleDp).model(m.parse().map_err(|_| {
                anyhow::anyhow!("--model {m}: one of ti, s, b, l, h (ScaleDP) or dp-t")
            })?),
        };
    }
    if a.layers.is_some() || a.width.is_some() || a.heads.is_some() {
        let (d, w, h) = o.get_denoiser();
        o = o.denoiser(
            a.layers.unwrap_or(d),
            a.width.unwrap_or(w),
            a.heads.unwrap_or(h),
        );
    }
    macro_rules! set {
        ($($field:ident),*) => {$(
            if let Some(v) = a.$field {
                o = o.$field(v);
            }
        )*};
    }
    set!(
        steps,
        batch_size,
        micro_batch,
        lr,
        warmup_steps,
        seed,
        checkpoint_every,
        val_every
    );
    set!(
        val_ratio,
        grad_clip,
        crop,
        obs_horizon,
        action_chunk,
        resnet_width,
        noise_samples,
        dropout
    );
    if let Some(s) = &a.image_size {
        let (w, h) = size(s)?;
        o = o.image_size(w, h);
    }
    if !a.cameras.is_empty() {
        o = o.cameras(a.cameras.clone());
    }
    if let Some(at) = &a.attention {
        o = o.attention(at.parse()?);
    }
    if let Some(p) = &a.pos_embed {
        o = o.pos_embed(p.parse()?);
    }
    if a.mask_padding {
        o = o.mask_padding(true);
    }
    if let Some(n) = &a.state_norm {
        o = o.state_norm(match n.as_str() {
            "min-max" | "min_max" => StateNorm::MinMax,
            "mean-std" | "mean_std" => StateNorm::MeanStd,
            other => bail!("--state-norm {other}: min-max or mean-std"),
        });
    }
    let mut adamw = o.get_adamw();
    if let Some(w) = a.weight_decay {
        adamw.weight_decay = w;
    }
    if let Some(w) = a.encoder_weight_decay {
        adamw.encoder_weight_decay = w;
    }
    Ok(o.adamw(adamw))
}

fn print_counts(what: &str, cfg: &ModelConfig) -> Result<()> {
    let n = ScaleDp::count(cfg)?;
    let (cw, ch) = cfg.crop_size();
    println!(
        "{what}: {} (depth {}, width {}, heads {}, {} attention, {} pos_embed), {} cameras {}x{} cropped to {cw}x{ch}, state {}, action {}, To {}, C {}",
        cfg.denoiser_name(),
        cfg.depth, cfg.hidden, cfg.heads, cfg.attention, cfg.pos_embed, cfg.cameras.len(), cfg.image_width, cfg.image_height,
        cfg.state_dim, cfg.action_dim, cfg.obs_horizon, cfg.action_chunk
    );
    println!(
        "denoiser parameters: {} ({:.2} M)",
        n.denoiser,
        n.denoiser as f64 / 1e6
    );
    println!(
        "encoder parameters:  {} ({:.2} M = {} cameras x {:.2} M)",
        n.encoders,
        n.encoders as f64 / 1e6,
        cfg.cameras.len(),
        n.encoder_per_camera as f64 / 1e6
    );
    println!(
        "total parameters:    {} ({:.2} M)",
        n.total(),
        n.total() as f64 / 1e6
    );
    Ok(())
}

/// Runs `scaledp train`.
pub fn run(a: TrainArgs) -> Result<ExitStatus> {
    let dev = shared::device(&a.device)?;
    let opts = options(&a)?;
    let model = opts.get_model();
    let mut trainer = match (&a.resume, &a.dataset) {
        (Some(run), _) => Trainer::resume(run, a.steps, &dev)?,
        (None, None) if a.dry_run => {
            let mut cfg = ModelConfig::paper(model);
            if opts.get_arch() == Architecture::DpT {
                let p = ModelConfig::paper(model);
                cfg = ModelConfig::dp_t(
                    p.cameras,
                    (p.image_width, p.image_height),
                    p.state_dim,
                    p.action_dim,
                );
            }
            let (depth, hidden, heads) = opts.get_denoiser();
            if (depth, hidden, heads) != (cfg.depth, cfg.hidden, cfg.heads) {
                (cfg.size, cfg.depth, cfg.hidden, cfg.heads) = (None, depth, hidden, heads);
            }
            if let Some(at) = &a.attention {
                cfg.attention = at.parse()?;
            }
            if let Some(p) = &a.pos_embed {
                cfg.pos_embed = p.parse()?;
                cfg.validate()?;
            }
            cfg.obs_horizon = a.obs_horizon.unwrap_or(cfg.obs_horizon);
            cfg.action_chunk = a.action_chunk.unwrap_or(cfg.action_chunk);
            print_counts("paper setup (3 cameras, 14-D state and action)", &cfg)?;
            return Ok(ExitStatus::Success);
        }
        (None, None) => bail!("name a DATASET (or --resume a run)"),
        (None, Some(ds)) if a.dry_run => {
            let cfg = Trainer::plan(ds, &opts)?;
            print_counts(ds, &cfg.model)?;
            return Ok(ExitStatus::Success);
        }
        (None, Some(ds)) => {
            let out = a
                .out
                .as_ref()
                .context("--out DIR is needed for a new run")?;
            Trainer::new(ds, out, opts, &dev)?
        }
    };
    if a.dry_run {
        print_counts(&trainer.config().dataset, &trainer.config().model)?;
        return Ok(ExitStatus::Success);
    }
    let stop = trainer.stop_flag();
    let int = shared::interrupt_flag();
    let total = trainer.options().get_steps();
    let bar = indicatif::ProgressBar::new(total).with_position(trainer.step_count());
    bar.set_style(indicatif::ProgressStyle::with_template(
        "{bar:30} {pos}/{len} steps  {msg}  [{elapsed_precise} < {eta_precise}]",
    )?);
    let curves = match &a.view {
        Some(url) => Some(shared::viewer::curves::Curves::start(
            url.as_deref(),
            &trainer.config().dataset,
        )?),
        None => None,
    };
    let mut view_error = None;
    let mut show = |r: anyhow::Result<()>| {
        if let Err(e) = r {
            view_error.get_or_insert(e);
        }
    };
    let (mut wait, mut busy) = (0f64, 0f64);
    let summary = trainer.run(|e| {
        if let Some(c) = &curves {
            match &e {
                Event::Step(r) => show(c.step(r.step, r.loss as f64, r.lr)),
                Event::Validation(v) => {
                    show(c.validation(v.step, "loss", v.loss as f64));
                    show(c.validation(v.step, "action_mse", v.action_mse));
                    for (n, err) in v.action_names.iter().zip(&v.action_mae_raw) {
                        show(c.validation(v.step, &format!("mae_{n}"), *err));
                    }
                }
                Event::Checkpoint(_) => {}
            }
        }
        if int.load(Ordering::Relaxed) {
            stop.store(true, Ordering::Relaxed);
        }
        match e {
            Event::Step(r) => {
                wait += r.data_wait_s;
                busy += r.step_s;
                bar.set_position(r.step);
                bar.set_message(format!(
                    "loss {:.4}  lr {:.2e}  {:.1} samples/s  data wait {:.0} %",
                    r.loss,
                    r.lr,
                    r.samples as f64 / r.step_s.max(1e-9),
                    100.0 * wait / busy.max(1e-9)
                ));
            }
            Event::Validation(v) => bar.println(format!(
                "step {}: val loss {:.4}, action MSE {:.4} (normalized), MAE per dim {:?}",
                v.step,
                v.loss,
                v.action_mse,
                v.action_names
                    .iter()
                    .zip(&v.action_mae_raw)
                    .map(|(n, e)| format!("{n} {e:.4}"))
                    .collect::<Vec<_>>()
            )),
            Event::Checkpoint(p) => bar.println(format!("checkpoint {}", p.display())),
        }
    })?;
    bar.finish_and_clear();
    if let Some(c) = curves {
        c.finish()?;
    }
    if let Some(e) = view_error {
        eprintln!("warning: the viewer stopped taking the curves: {e:#}");
    }
    println!(
        "{} steps, final loss {}, data wait {:.1} % of step time, checkpoint {}",
        summary.steps,
        summary.final_loss.map_or("-".into(), |l| format!("{l:.4}")),
        100.0 * summary.data_wait_share,
        summary
            .checkpoint
            .as_ref()
            .map_or("-".into(), |p| p.display().to_string())
    );
    Ok(ExitStatus::Success)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        train: TrainArgs,
    }

    /// (architecture, attention) of the options `scaledp train ds <flags>` starts a run with.
    fn picked(flags: &[&str]) -> (String, String) {
        let cli = Cli::try_parse_from(["train", "ds"].iter().chain(flags)).unwrap();
        let o = serde_json::to_value(options(&cli.train).unwrap()).unwrap();
        (o["arch"].to_string(), o["attention"].to_string())
    }

    #[test]
    fn scaledp_trains_causal_by_default_and_the_paper_preset_keeps_its_non_causal_attention() {
        let (scaledp, dpt) = ("\"scale_dp\"", "\"dp_t\"");
        let (causal, non_causal) = ("\"causal\"", "\"non_causal\"");
        for (flags, want) in [
            (&[][..], (scaledp, causal)),
            (&["--model", "s"], (scaledp, causal)),
            (&["--preset", "cpu-aloha"], (scaledp, causal)),
            (&["--preset", "paper"], (scaledp, non_causal)),
            (
                &["--preset", "paper", "--model", "s"],
                (scaledp, non_causal),
            ),
            (&["--preset", "paper", "--model", "dp-t"], (dpt, causal)),
            (
                &["--preset", "cpu-aloha", "--attention", "non-causal"],
                (scaledp, non_causal),
            ),
            (
                &["--model", "dp-t", "--attention", "non-causal"],
                (dpt, non_causal),
            ),
        ] {
            let (arch, attention) = picked(flags);
            assert_eq!((arch.as_str(), attention.as_str()), want, "{flags:?}");
        }
    }
}
