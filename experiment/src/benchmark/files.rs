//! A benchmark's result files: one per (task, arm, training seed) and one per task for its
//! controls, where they live, and where each arm's run directory is.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::audit::Audit;
use crate::figures::{Controls, EvalFigures};

/// One (task, arm) result: `RESULTS/NAME/<task>--<arm>.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskResult {
    /// `metaworld`, `aloha`.
    pub benchmark: String,
    /// The task (`assembly`).
    pub task: String,
    /// Its level (MetaWorld's `easy`, `medium`, `hard`, `very hard`; ALOHA's `bimanual`).
    pub level: String,
    /// The arm (`ti`, `dp-t`).
    pub arm: String,
    /// Its training seed (0 unless `--train-seed`: a replicate).
    #[serde(default)]
    pub train_seed: u64,
    /// What it is.
    pub what: String,
    /// Test-seed success rate of the last checkpoint (0–1): the reported figure.
    pub test_success_rate: f64,
    /// The test seeds.
    pub test_seeds: Vec<u64>,
    /// 95 % Wilson interval of the test success rate.
    pub wilson_low: f64,
    /// 95 % Wilson interval of the test success rate.
    pub wilson_high: f64,
    /// The test evaluation in full.
    pub test: EvalFigures,
    /// Hours of training (Σ of the steps' wall times).
    pub train_hours: f64,
    /// Optimizer steps.
    pub steps: u64,
    /// Mean wall time of a step (s).
    pub step_s: f64,
    /// The checkpoint scored.
    pub checkpoint: String,
    /// Denoiser parameters.
    pub denoiser_params: usize,
    /// Encoder parameters.
    pub encoder_params: usize,
    /// Successful demonstrations trained on.
    pub demonstrations: u64,
    /// The command that produced this file.
    pub command: String,
    /// The equivalent `scaledp train` command.
    pub train_command: String,
    /// The training settings.
    pub train_options: serde_json::Value,
    /// Who trained and scored it, on what, from which demonstrations.
    pub audit: Audit,
    /// What the file said before each re-score (`compare --rescore`), the oldest first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub earlier_scores: Vec<Earlier<EvalFigures>>,
    /// The command of the latest re-score, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rescore_command: Option<String>,
}

/// A task's controls: `RESULTS/NAME/<task>--controls.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskControls {
    /// The task.
    pub task: String,
    /// Its level.
    pub level: String,
    /// The arm whose checkpoints the untrained and frozen controls use.
    pub arm: String,
    /// The controls.
    pub controls: Controls,
    /// Who trained the arm's checkpoints and who scored the controls.
    pub audit: Audit,
    /// What the file said before each re-score (`compare --rescore`), the oldest first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub earlier_scores: Vec<Earlier<Controls>>,
    /// The command of the latest re-score, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rescore_command: Option<String>,
}

/// The file of (task, arm) trained from `seed`.
pub(super) fn result_path(dir: &Path, task: &str, arm: &str, seed: u64) -> PathBuf {
    match seed {
        0 => dir.join(format!("{task}--{arm}.json")),
        s => dir.join(format!("{task}--{arm}--seed{s}.json")),
    }
}

/// Whether every file a `compare` call would write for `task` is already in `dir`: each arm's
/// result from `seed` and, if `controls`, the task's controls. Such a task is skipped whole, so
/// a machine that lacks its demonstrations does not collect them again.
pub(super) fn landed(dir: &Path, task: &str, arms: &[&str], seed: u64, controls: bool) -> bool {
    (!controls || dir.join(format!("{task}--controls.json")).exists())
        && arms
            .iter()
            .all(|arm| result_path(dir, task, arm, seed).exists())
}

/// The run directory of an arm trained from `seed`.
pub(super) fn run_dir(task_dir: &Path, arm: &str, seed: u64) -> PathBuf {
    match seed {
        0 => task_dir.join(arm),
        s => task_dir.join(format!("{arm}-seed{s}")),
    }
}

/// What a result file said before a re-score.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Earlier<T> {
    /// The figures then.
    pub figures: T,
    /// Who scored them, with what simulator.
    pub audit: Audit,
}

impl TaskResult {
    /// A test fixture: `arm` on transfer-cube from `seed`, `successes` of 50 test seeds.
    #[cfg(test)]
    pub(crate) fn fixture(arm: &str, seed: u64, successes: u64) -> TaskResult {
        let test = EvalFigures::counts(successes, 50);
        TaskResult {
            benchmark: "aloha".into(),
            task: "transfer-cube".into(),
            level: "bimanual".into(),
            arm: arm.into(),
            train_seed: seed,
            what: arm.into(),
            test_success_rate: test.success_rate,
            test_seeds: (3_000_000..3_000_050).collect(),
            wilson_low: 0.1,
            wilson_high: 0.9,
            test,
            train_hours: 1.0,
            steps: 2500,
            step_s: 1.3,
            checkpoint: "ckpt".into(),
            denoiser_params: 1,
            encoder_params: 1,
            demonstrations: 50,
            command: "c".into(),
            train_command: "t".into(),
            train_options: serde_json::Value::Null,
            audit: crate::audit::Audit::fixture(seed),
            earlier_scores: Vec::new(),
            rescore_command: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_task_has_landed_only_when_every_arm_and_its_controls_have() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let touch = |name: &str| std::fs::write(d.join(name), "{}").unwrap();
        touch("assembly--ti.json");
        assert!(!landed(d, "assembly", &["ti", "ti-causal"], 0, false));
        touch("assembly--ti-causal.json");
        assert!(landed(d, "assembly", &["ti", "ti-causal"], 0, false));
        assert!(!landed(d, "assembly", &["ti", "ti-causal"], 0, true));
        assert!(!landed(d, "assembly", &["ti"], 1, false));
        touch("assembly--controls.json");
        assert!(landed(d, "assembly", &["ti", "ti-causal"], 0, true));
        assert!(!landed(d, "hand-insert", &["ti"], 0, false));
    }
}
