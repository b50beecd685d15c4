//! Closed-loop evaluations of an arm's checkpoints, each cached beside what it evaluated
//! (`eval-<what>-seed<S>-n<N>.json`), so an interrupted experiment resumes without redoing
//! finished ones.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use candle_core::Device;
use indicatif::{ProgressBar, ProgressStyle};
use scaledp_deploy::{
    run_eval, run_expert, ControlOptions, EpisodeReport, EvalOptions, EvalReport, Split,
};
use scaledp_policy::Policy;
use scaledp_schema::Rig;

/// How the evaluations run.
#[derive(Debug, Clone)]
pub struct EvalPlan {
    /// Longest episode (simulated s).
    pub max_seconds: f64,
    /// Actions executed per chunk.
    pub action_steps: usize,
    /// Run every evaluation again even where a cache file holds it, and cache the new one (a
    /// re-score with this build's simulator).
    pub fresh: bool,
}

impl EvalPlan {
    fn options(&self, split: Split, episodes: u64, freeze_cameras: bool) -> EvalOptions {
        EvalOptions {
            episodes,
            seed: split.first_seed(),
            max_seconds: self.max_seconds,
            control: ControlOptions {
                action_steps: self.action_steps,
                freeze_cameras,
                ..ControlOptions::default()
            },
            ..EvalOptions::default()
        }
    }
}

/// What an evaluation runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// The checkpoint in simulated time.
    Policy,
    /// The checkpoint with its cameras frozen on each episode's first frames.
    Frozen,
    /// The checkpoint in real time (sim + serve over loopback Zenoh).
    Live,
}

fn cached(path: &Path) -> Option<EvalReport> {
    let bytes = std::fs::read(path).ok()?;
    serde_json::from_slice(&bytes).ok()
}

fn bar(n: u64, what: &str) -> ProgressBar {
    let b = ProgressBar::new(n).with_style(
        ProgressStyle::with_template("  {msg} {bar:24} {pos}/{len} episodes [{elapsed_precise}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    b.set_message(what.to_string());
    b
}

/// The report of `kind` for `checkpoint` on `episodes` seeds of `split`, from its cache file or
/// run now (and cached).
pub fn checkpoint(
    checkpoint: &Path,
    rig: Option<&Rig>,
    kind: Kind,
    split: Split,
    episodes: u64,
    plan: &EvalPlan,
) -> Result<EvalReport> {
    let opts = plan.options(split, episodes, kind == Kind::Frozen);
    let tag = match kind {
        Kind::Policy => "",
        Kind::Frozen => "-frozen",
        Kind::Live => "-live",
    };
    let path = checkpoint.join(
        format!(
            "eval-{split:?}-seed{}-n{episodes}-a{}{tag}.json",
            opts.seed, plan.action_steps
        )
        .to_lowercase(),
    );
    if let Some(r) = cached(&path).filter(|_| !plan.fresh) {
        return Ok(r);
    }
    let policy = Policy::load(checkpoint, &Device::Cpu)?;
    let rig = match rig {
        Some(r) => r.clone(),
        None => trained_rig(&policy)?,
    };
    let b = bar(
        episodes,
        &format!("{} {kind:?} {split:?}", checkpoint.display()),
    );
    let mut on = |_: &EpisodeReport| b.inc(1);
    let report = match kind {
        Kind::Live => {
            let session = scaledp_recorder::net::open_private()?;
            scaledp_deploy::run_live(policy.dir(), &Device::Cpu, &rig, &opts, &session, &mut on)?
        }
        _ => run_eval(&policy, &rig, &opts, &mut on)?,
    };
    b.finish_and_clear();
    report.write(&path)?;
    Ok(report)
}

/// The scripted expert on `episodes` seeds of `split`, cached in `dir`.
pub fn expert(
    dir: &Path,
    rig: &Rig,
    split: Split,
    episodes: u64,
    plan: &EvalPlan,
) -> Result<EvalReport> {
    let opts = plan.options(split, episodes, false);
    let path = dir
        .join(format!("eval-expert-{split:?}-seed{}-n{episodes}.json", opts.seed).to_lowercase());
    if let Some(r) = cached(&path).filter(|_| !plan.fresh) {
        return Ok(r);
    }
    let b = bar(episodes, "scripted expert");
    let report = run_expert(rig, &opts, &mut |_| b.inc(1))?;
    b.finish_and_clear();
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    report.write(&path)?;
    Ok(report)
}

/// The rig a checkpoint was trained on.
pub fn trained_rig(policy: &Policy) -> Result<Rig> {
    let ckpt = policy.dir().display().to_string();
    match scaledp_deploy::check::trained_rig(policy.config(), &ckpt)? {
        Some(rig) => Ok(rig),
        None => anyhow::bail!("checkpoint {ckpt} names no rig"),
    }
}

/// The checkpoint directories of a run, by step.
pub fn checkpoints(run: &Path) -> Result<Vec<(u64, PathBuf)>> {
    Ok(scaledp_policy::list_checkpoints(run)?)
}

/// The chosen step: the highest validation success rate, the later checkpoint on a tie.
pub fn select(points: &[(u64, u64)]) -> Option<u64> {
    points
        .iter()
        .copied()
        .max_by(|a, b| a.1.cmp(&b.1).then(a.0.cmp(&b.0)))
        .map(|p| p.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_best_validation_checkpoint_wins_and_ties_go_to_the_later_one() {
        assert_eq!(
            select(&[(0, 0), (1000, 12), (2000, 15), (3000, 15), (4000, 9)]),
            Some(3000)
        );
        assert_eq!(select(&[]), None);
    }
}
