//! The controller settings `serve` and `eval` share, and the rig a checkpoint runs on.

use anyhow::{bail, Context, Result};
use clap::Args;
use scaledp_deploy::{ControlOptions, Workspace};
use scaledp_policy::Policy;
use scaledp_schema::Rig;

/// The controller settings `serve` and `eval` share.
#[derive(Debug, Clone, Args)]
pub struct ControlArgs {
    /// Actions executed per predicted chunk (receding horizon), 1 … the checkpoint's chunk
    /// [half the checkpoint's chunk, as diffusion_policy: 8 of 16].
    #[arg(long)]
    pub action_steps: Option<usize>,
    /// Workspace box of the TCP targets in the arm's base frame, xmin,ymin,zmin,xmax,ymax,zmax
    /// (m): once for every arm, or once per arm in rig order (default: the simulated cell's
    /// work region of each arm, 12 cm wider, from 5 mm to 45 cm above the table).
    #[arg(long, value_name = "BOX")]
    pub workspace: Vec<String>,
    /// Largest TCP translation per control tick (m).
    #[arg(long, default_value_t = 0.05)]
    pub max_step_m: f64,
    /// Largest TCP rotation per control tick (rad).
    #[arg(long, default_value_t = 0.25)]
    pub max_step_rad: f64,
    /// How far the observation tick runs behind the clock (ms), so joints have a sample after
    /// it and the tick's camera frames have arrived.
    #[arg(long, default_value_t = 50.0)]
    pub obs_lag_ms: f64,
    /// Stop commanding when a camera or arm stream is silent for more than this many of its
    /// periods…
    #[arg(long, default_value_t = 2.0)]
    pub stale_periods: f64,
    /// …but never for less than this (ms): two periods of a 1 kHz arm are shorter than a busy
    /// machine's scheduling jitter.
    #[arg(long, default_value_t = 50.0)]
    pub min_silence_ms: f64,
    /// cpu, or cuda (a build with the `cuda` feature of scaledp-policy).
    #[arg(long, default_value = "cpu")]
    pub device: String,
}

impl ControlArgs {
    /// The controller options for `rig` and a checkpoint predicting `chunk` actions at a time.
    pub fn options(&self, rig: &Rig, chunk: usize) -> Result<ControlOptions> {
        let boxes = self
            .workspace
            .iter()
            .map(|w| {
                Workspace::parse(w).with_context(|| {
                    format!("--workspace {w}: six numbers xmin,ymin,zmin,xmax,ymax,zmax, min ≤ max")
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let workspace = match boxes.len() {
            0 => None,
            1 => Some(vec![boxes[0]; rig.arms.len()]),
            n if n == rig.arms.len() => Some(boxes),
            n => bail!(
                "{n} --workspace boxes for the {} arms of rig {}",
                rig.arms.len(),
                rig.name
            ),
        };
        Ok(ControlOptions {
            action_steps: self.action_steps.unwrap_or((chunk / 2).max(1)),
            workspace,
            max_step_m: self.max_step_m,
            max_step_rad: self.max_step_rad,
            obs_lag_s: self.obs_lag_ms * 1e-3,
            stale_periods: self.stale_periods,
            min_silence_s: self.min_silence_ms * 1e-3,
            ..ControlOptions::default()
        })
    }
}

/// The rig named, else the checkpoint's own (the rig stored with its training data).
pub fn rig_for(policy: &Policy, rig: Option<&str>) -> Result<Rig> {
    if let Some(r) = rig {
        return Ok(Rig::load_or_builtin(r)?);
    }
    let ckpt = policy.dir().display().to_string();
    match scaledp_deploy::check::trained_rig(policy.config(), &ckpt)? {
        Some(rig) => Ok(rig),
        None => bail!("checkpoint {ckpt} names no rig: pass --rig"),
    }
}
