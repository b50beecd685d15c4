//! An arm's result file (a `--dataset` comparison) and the experiment's table, rebuilt from
//! whatever arms are there.

use std::path::Path;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use crate::figures::{Controls, EvalFigures, ValPoint};
use crate::significance::{self, Pairing, RECIPE};

/// One arm's result: `RESULTS/NAME/<arm>.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ArmResult {
    /// The arm (`ti`, `ti-causal`, `s`).
    pub arm: String,
    /// What it is.
    pub what: String,
    /// The command that produced this file.
    pub command: String,
    /// The equivalent `scaledp train` command of the arm's run.
    pub train_command: String,
    /// The training settings (the preset with the arm's model and attention).
    pub train_options: serde_json::Value,
    /// The dataset.
    pub dataset: String,
    /// Optimizer steps trained.
    pub steps: u64,
    /// Hours of training: the sum of the steps' wall times (resumed sessions included).
    pub train_hours: f64,
    /// Mean wall time of a step (s).
    pub step_s: f64,
    /// Denoiser parameters.
    pub denoiser_params: usize,
    /// Encoder parameters (all cameras).
    pub encoder_params: usize,
    /// Every checkpoint on the validation seeds.
    pub validation: Vec<ValPoint>,
    /// The checkpoint chosen on them (highest validation success; the later one on a tie).
    pub selected_step: u64,
    /// Its test-seed success rate (0–1): the reported figure.
    pub test_success_rate: f64,
    /// The test seeds.
    pub test_seeds: Vec<u64>,
    /// 95 % Wilson interval of the test success rate.
    pub wilson_low: f64,
    /// 95 % Wilson interval of the test success rate.
    pub wilson_high: f64,
    /// The test evaluation in full.
    pub test: EvalFigures,
    /// The chosen checkpoint in real time over loopback Zenoh, when run.
    pub live: Option<EvalFigures>,
    /// The controls, when run.
    pub controls: Controls,
    /// Who trained and scored it (the demonstrations' collection is not known to a
    /// `--dataset` comparison, so such a file cannot pass the schema until it names them).
    pub audit: crate::audit::Audit,
}

/// Reads every `*.json` arm result in `dir`, in the arms' order.
pub fn read_all(dir: &Path) -> Result<Vec<ArmResult>> {
    let mut out = Vec::new();
    for arm in crate::arms::ARMS {
        let path = dir.join(format!("{}.json", arm.name));
        if !path.exists() {
            continue;
        }
        let bytes = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
        out.push(
            serde_json::from_slice(&bytes)
                .with_context(|| format!("{}: not an arm result", path.display()))?,
        );
    }
    Ok(out)
}

/// The Markdown table of `arms` (and their controls).
pub fn table(arms: &[ArmResult]) -> String {
    let mut s = String::from(
        "| arm | steps | training | s/step | chosen step (val) | test success (95 % Wilson) | mean time to success | inference p50 / p99 |\n|---|---|---|---|---|---|---|---|\n",
    );
    let ms = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.0}"));
    for a in arms {
        let val = a
            .validation
            .iter()
            .find(|v| v.step == a.selected_step)
            .map_or("–".into(), |v| {
                format!("{} ({}/{})", v.step, v.successes, v.episodes)
            });
        s.push_str(&format!(
            "| {} | {} | {:.2} h | {:.2} | {} | {} | {} | {} / {} ms |\n",
            a.what,
            a.steps,
            a.train_hours,
            a.step_s,
            val,
            a.test.cell(),
            a.test
                .mean_time_to_success_s
                .map_or("–".into(), |t| format!("{t:.1} s")),
            ms(a.test.inference_ms_p50),
            ms(a.test.inference_ms_p99),
        ));
    }
    let mut controls = String::new();
    for a in arms {
        let rows = [
            (
                "chosen checkpoint, live (real time, serve over loopback Zenoh)",
                a.live.as_ref(),
            ),
            ("untrained weights (step 0)", a.controls.untrained.as_ref()),
            (
                "chosen checkpoint, cameras frozen on the first frame",
                a.controls.frozen_cameras.as_ref(),
            ),
            (
                "the scripted expert that recorded the demonstrations",
                a.controls.scripted_expert.as_ref(),
            ),
        ];
        for (what, f) in rows {
            if let Some(f) = f {
                let extra = match (f.median_time_to_success_s, f.e2e_ms_p50) {
                    (Some(t), Some(e)) => {
                        format!("median time to success {t:.1} s, frame→command p50 {e:.0} ms")
                    }
                    (Some(t), None) => format!("median time to success {t:.1} s"),
                    _ => String::new(),
                };
                controls.push_str(&format!(
                    "| {} | {what} | {} | {extra} |\n",
                    a.arm,
                    f.cell()
                ));
            }
        }
    }
    if !controls.is_empty() {
        s.push_str(
            "\n| arm | control (test seeds) | success (95 % Wilson) | |\n|---|---|---|---|\n",
        );
        s.push_str(&controls);
    }
    if let Some(recipe) = arms.iter().find(|a| a.arm == RECIPE) {
        let pairings: Vec<Pairing> = arms
            .iter()
            .filter(|a| a.arm != RECIPE)
            .map(|a| Pairing {
                task: "",
                arm: &a.arm,
                seed: 0,
                recipe: &recipe.test,
                other: &a.test,
            })
            .collect();
        s.push_str(&significance::table(&pairings, false));
    }
    s
}
