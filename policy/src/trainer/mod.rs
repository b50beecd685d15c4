//! The trainer: loader batches → masked ε-prediction loss → AdamW (cosine schedule, optional
//! clipping) → EMA; validation, checkpoints, `metrics.jsonl`, exact resume.
//!
//! Every random draw of step k (crops, timesteps, noise) comes from a generator seeded by
//! (seed, k), so a resumed run draws exactly what an uninterrupted one would; the data order is
//! the loader's, resumed from its saved position.

pub(crate) mod checkpointing;
mod loss;
pub(crate) mod optim;
mod options;
mod presets;
mod spec;
mod validate;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use candle_core::Device;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use scaledp_datasets::{Batch, Loader, LoaderOptions, Norm, Split};
use serde::Serialize;

use crate::checkpoint::CheckpointConfig;
use crate::error::{Error, Result};
use crate::model::params::Param;
use crate::model::ScaleDp;
use crate::scheduler::NoiseScheduler;
pub(crate) use loss::{candle_loss_and_grads, loss_and_grads};
use optim::AdamW;
pub use optim::{AdamWConfig, EmaConfig};
pub use options::{cosine_lr, default_attention, StateNorm, TrainOptions};
pub use presets::PRESETS;
pub use spec::{LossSpec, Phases};
pub use validate::ValRecord;

/// What one optimizer step did (one line of `metrics.jsonl`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StepRecord {
    /// Steps done, this one included.
    pub step: u64,
    /// The batch's masked ε-MSE.
    pub loss: f32,
    /// Learning rate of this update.
    pub lr: f64,
    /// Global gradient norm before clipping (computed when clipping is on).
    pub grad_norm: Option<f64>,
    /// Samples in the batch.
    pub samples: usize,
    /// Wall time of the whole step (s).
    pub step_s: f64,
    /// Part of it spent waiting for the loader (s).
    pub data_wait_s: f64,
    /// Where the rest went: encoders, denoiser and loss, backward pass (s).
    pub phases: Phases,
    /// AdamW and the EMA (s).
    pub optimizer_s: f64,
    /// The loader's epoch.
    pub epoch: u64,
}

/// What the trainer reports while it runs (for progress bars and logs: the library draws
/// nothing itself).
#[derive(Clone, Debug)]
pub enum Event {
    /// A step finished.
    Step(StepRecord),
    /// A validation finished.
    Validation(ValRecord),
    /// A checkpoint was written.
    Checkpoint(PathBuf),
}

/// How a run ended.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// Steps done in total.
    pub steps: u64,
    /// The last checkpoint.
    pub checkpoint: Option<PathBuf>,
    /// Mean loss of the last (up to) 50 steps of this run.
    pub final_loss: Option<f32>,
    /// Share of step time spent waiting for the loader in this run.
    pub data_wait_share: f64,
    /// Whether [`Trainer::stop_flag`] ended it early.
    pub interrupted: bool,
}

/// A training run in a directory (`metrics.jsonl`, `checkpoints/step_*`).
pub struct Trainer {
    opts: TrainOptions,
    out: PathBuf,
    loader: Loader,
    val: Option<Loader>,
    /// Inputs, normalizer and provenance; `step`, `loader` and `train` are filled at each save.
    cfg: CheckpointConfig,
    model: ScaleDp,
    ema_model: ScaleDp,
    ema_params: Vec<Param>,
    optim: AdamW,
    scheduler: NoiseScheduler,
    step: u64,
    metrics: std::io::BufWriter<std::fs::File>,
    stop: Arc<AtomicBool>,
    last_checkpoint: Option<PathBuf>,
    /// The CPU engine's buffers (unused on other devices).
    engine: crate::engine::Engine,
}

impl std::fmt::Debug for Trainer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Trainer")
            .field("out", &self.out)
            .field("step", &self.step)
            .finish_non_exhaustive()
    }
}

/// The generator of step `step`'s draws.
pub(crate) fn step_rng(seed: u64, step: u64) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    r.set_stream(step);
    r
}

/// Opens the training (and, with a validation ratio, validation) loaders of a run.
fn open_loaders(dataset: &str, o: &TrainOptions) -> Result<(Loader, Option<Loader>)> {
    let base = |split: Split, shuffle: bool| {
        let mut l = LoaderOptions::default()
            .obs_horizon(o.obs_horizon)
            .action_chunk(o.action_chunk)
            .batch_size(o.batch_size)
            .split(split)
            .val_ratio(o.val_ratio)
            .split_seed(o.seed)
            .seed(o.seed)
            .shuffle(shuffle)
            .threads(o.loader_threads)
            .state_norm(o.state_norm.loader())
            .action_norm(Norm::MinMax);
        if let Some(c) = &o.cameras {
            l = l.cameras(c.clone());
        }
        if let Some((w, h)) = o.image_size {
            l = l.image_size(w, h);
        }
        if let (Some(n), Split::Train) = (o.max_episodes, split) {
            l = l.max_episodes(n);
        }
        l
    };
    let train_split = if o.val_ratio > 0.0 {
        Split::Train
    } else {
        Split::All
    };
    // Full batches only, unless the split is smaller than one batch.
    let mut loader = base(train_split, true)
        .drop_incomplete_batch(true)
        .open(dataset)?;
    if loader.is_empty() {
        loader = base(train_split, true).open(dataset)?;
    }
    let val = if o.val_ratio > 0.0 {
        match base(Split::Val, true).open(dataset) {
            Ok(v) => Some(v),
            Err(scaledp_datasets::Error::Options(m)) if m.contains("no samples") => {
                tracing::warn!(
                    "{dataset}: no validation episodes at val_ratio {}",
                    o.val_ratio
                );
                None
            }
            Err(e) => return Err(e.into()),
        }
    } else {
        None
    };
    Ok((loader, val))
}

impl Trainer {
    /// A new run training on `dataset` (a directory or `s3://…`) into `out`, which must not
    /// hold checkpoints already (resume those with [`Trainer::resume`]).
    pub fn new(dataset: &str, out: &Path, opts: TrainOptions, device: &Device) -> Result<Self> {
        if !crate::checkpoint::list(out)?.is_empty() {
            return Err(Error::Config(format!(
                "{} already holds checkpoints: resume it, or choose another --out",
                out.display()
            )));
        }
        if opts.steps == 0 || opts.batch_size == 0 {
            return Err(Error::Config(
                "steps and batch size must be at least 1".into(),
            ));
        }
        let (loader, val) = open_loaders(dataset, &opts)?;
        let cfg = checkpointing::config_for(dataset, &loader, &opts)?;
        let (model, params) = ScaleDp::fresh(&cfg.model, opts.seed, device)?;
        let (ema_model, ema_params) = checkpointing::copy_model(&cfg.model, &params, device)?;
        std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
        let path = out.join("metrics.jsonl");
        let file = std::fs::File::create(&path).map_err(|e| Error::io(&path, e))?;
        Ok(Trainer {
            optim: AdamW::new(params, opts.adamw)?,
            scheduler: NoiseScheduler::new(cfg.diffusion.train_steps)?,
            opts,
            out: out.to_path_buf(),
            loader,
            val,
            cfg,
            model,
            ema_model,
            ema_params,
            step: 0,
            metrics: std::io::BufWriter::new(file),
            stop: Arc::new(AtomicBool::new(false)),
            last_checkpoint: None,
            engine: Default::default(),
        })
    }

    /// The configuration a run on `dataset` with `opts` would get (inputs, model, normalizer),
    /// without building the model: for dry runs and parameter counts.
    pub fn plan(dataset: &str, opts: &TrainOptions) -> Result<CheckpointConfig> {
        let (loader, _) = open_loaders(dataset, opts)?;
        checkpointing::config_for(dataset, &loader, opts)
    }

    /// Continues the run in `run` from its latest checkpoint: same weights, optimizer state,
    /// data position and random streams. `steps` changes the total (the cosine schedule
    /// stretches with it).
    pub fn resume(run: &Path, steps: Option<u64>, device: &Device) -> Result<Self> {
        checkpointing::resume(run, steps, device)
    }

    /// A flag that, once set (from a Ctrl-C handler, say), makes [`Trainer::run`] write a
    /// checkpoint and return after the current step.
    pub fn stop_flag(&self) -> Arc<AtomicBool> {
        self.stop.clone()
    }

    /// Steps done.
    pub fn step_count(&self) -> u64 {
        self.step
    }

    /// The options.
    pub fn options(&self) -> &TrainOptions {
        &self.opts
    }

    /// The model's configuration.
    pub fn config(&self) -> &CheckpointConfig {
        &self.cfg
    }

    /// The training loader (its dataset info and normalizer).
    pub fn loader(&self) -> &Loader {
        &self.loader
    }

    /// The network being trained (raw weights).
    pub fn model(&self) -> &ScaleDp {
        &self.model
    }

    /// The EMA of the weights (what checkpoints export).
    pub fn ema_model(&self) -> &ScaleDp {
        &self.ema_model
    }

    /// The next batch, starting a new epoch when one ends.
    fn next_batch(&mut self) -> Result<Batch> {
        for _ in 0..2 {
            match self.loader.next_batch() {
                Some(b) => return Ok(b?),
                None => {
                    let e = self.loader.state().epoch + 1;
                    self.loader.set_epoch(e);
                }
            }
        }
        Err(Error::Config(format!(
            "{}: the training split yields no batches",
            self.cfg.dataset
        )))
    }

    /// One optimizer step on the next batch.
    pub fn step(&mut self) -> Result<StepRecord> {
        self.step_inspect(&mut |_, _| {})
    }

    /// [`Trainer::step`], showing `inspect` every trained parameter's gradient (by name, before
    /// clipping and the update; fixed tables have none): for measurements of the training itself, such as the spread
    /// of gradient norms across blocks.
    pub fn step_inspect(
        &mut self,
        inspect: &mut dyn FnMut(&str, &candle_core::Tensor),
    ) -> Result<StepRecord> {
        let t0 = Instant::now();
        let batch = self.next_batch()?;
        let wait = t0.elapsed().as_secs_f64();
        check_finite(&batch)?;
        let mut rng = step_rng(self.opts.seed, self.step);
        let lr = cosine_lr(
            self.opts.lr,
            self.step,
            self.opts.warmup_steps,
            self.opts.steps,
        );
        let micro = self.opts.micro_batch;
        let mut phases = Phases::default();
        let (loss, mut grads) = loss_and_grads(
            &self.model,
            &mut self.engine,
            &self.scheduler,
            self.optim.params(),
            &batch,
            self.opts.loss,
            micro,
            &mut rng,
            &mut phases,
        )?;
        for (p, g) in self.optim.params().iter().zip(grads.iter_mut()) {
            if p.frozen {
                // A fixed table (requires_grad=False): no update, no part in the clipping norm.
                *g = None;
            }
            if let Some(g) = g {
                inspect(&p.name, g);
            }
        }
        let t_opt = Instant::now();
        if !loss.is_finite() {
            return Err(Error::Diverged {
                step: self.step + 1,
                loss,
            });
        }
        let (norm, scale) = match self.opts.grad_clip {
            Some(max) => {
                let n = AdamW::grad_norm(&grads)?;
                (Some(n), (max / (n + 1e-6)).min(1.0))
            }
            None => (None, 1.0),
        };
        self.optim.step(&grads, lr, scale)?;
        optim::ema_update(
            &self.ema_params,
            self.optim.params(),
            self.opts.ema.decay(self.step),
        )?;
        let optimizer_s = t_opt.elapsed().as_secs_f64();
        self.step += 1;
        let samples = batch.len;
        self.loader.recycle(batch);
        let rec = StepRecord {
            step: self.step,
            loss,
            lr,
            grad_norm: norm,
            samples,
            step_s: t0.elapsed().as_secs_f64(),
            data_wait_s: wait,
            phases,
            optimizer_s,
            epoch: self.loader.state().epoch,
        };
        self.log(&serde_json::json!({"kind": "train", "record": &rec}))?;
        Ok(rec)
    }

    /// Validates on the held-out episodes (`None` without any).
    pub fn validate(&mut self) -> Result<Option<ValRecord>> {
        let Some(val) = self.val.as_mut() else {
            return Ok(None);
        };
        let rec = validate::run(
            &self.ema_model,
            &self.cfg,
            val,
            self.opts.val_batches,
            self.opts.seed,
            self.step,
        )?;
        self.log(&serde_json::json!({"kind": "val", "record": &rec}))?;
        Ok(Some(rec))
    }

    /// Writes a checkpoint of the current step.
    pub fn save_checkpoint(&mut self) -> Result<PathBuf> {
        self.metrics.flush().map_err(|e| Error::io(&self.out, e))?;
        let dir = checkpointing::save(self)?;
        self.last_checkpoint = Some(dir.clone());
        Ok(dir)
    }

    /// Trains until the total step count, validating and saving as the options say, and
    /// always saving at the end (or when stopped). `on` sees every event.
    pub fn run(&mut self, mut on: impl FnMut(&Event)) -> Result<Summary> {
        let (mut wait, mut busy) = (0f64, 0f64);
        let mut recent = std::collections::VecDeque::new();
        let mut interrupted = false;
        // The untrained weights as step 0: the control of a success-rate curve.
        if self.step == 0 && self.opts.checkpoint_every > 0 && self.last_checkpoint.is_none() {
            let dir = self.save_checkpoint()?;
            on(&Event::Checkpoint(dir));
        }
        while self.step < self.opts.steps {
            if self.stop.load(Ordering::Relaxed) {
                interrupted = true;
                break;
            }
            let rec = self.step()?;
            wait += rec.data_wait_s;
            busy += rec.step_s;
            recent.push_back(rec.loss);
            if recent.len() > 50 {
                recent.pop_front();
            }
            on(&Event::Step(rec));
            let k = self.step;
            if self.opts.val_every > 0 && k % self.opts.val_every == 0 && k < self.opts.steps {
                if let Some(v) = self.validate()? {
                    on(&Event::Validation(v));
                }
            }
            if self.opts.checkpoint_every > 0
                && k % self.opts.checkpoint_every == 0
                && k < self.opts.steps
            {
                let dir = self.save_checkpoint()?;
                on(&Event::Checkpoint(dir));
            }
        }
        if self.opts.val_every > 0 && !interrupted {
            if let Some(v) = self.validate()? {
                on(&Event::Validation(v));
            }
        }
        let dir = self.save_checkpoint()?;
        on(&Event::Checkpoint(dir.clone()));
        Ok(Summary {
            steps: self.step,
            checkpoint: Some(dir),
            final_loss: (!recent.is_empty())
                .then(|| recent.iter().sum::<f32>() / recent.len() as f32),
            data_wait_share: if busy > 0.0 { wait / busy } else { 0.0 },
            interrupted,
        })
    }

    fn log(&mut self, v: &serde_json::Value) -> Result<()> {
        let path = self.out.join("metrics.jsonl");
        writeln!(self.metrics, "{v}")
            .and_then(|()| self.metrics.flush())
            .map_err(|e| Error::io(&path, e))
    }
}

/// Refuses a batch holding a non-finite state or action value, naming its sample.
fn check_finite(b: &Batch) -> Result<()> {
    for (what, values, per) in [
        ("state", &b.state, b.obs_horizon * b.state_dim),
        ("action", &b.action, b.action_chunk * b.action_dim),
    ] {
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            let s = i / per.max(1);
            return Err(Error::NonFinite {
                what,
                episode: b.episode_index.get(s).copied().unwrap_or(-1),
                frame: b.frame_index.get(s).copied().unwrap_or(-1),
            });
        }
    }
    Ok(())
}
