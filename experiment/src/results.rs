//! An arm's result file and the experiment's table, rebuilt from whatever arms are there.

use std::path::Path;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use crate::significance::{self, Pairing, RECIPE};

/// The key of a bridged simulator's behaviour among its versions.
pub const BRIDGE_VERSION: &str = "scaledp-bridge";

/// One evaluation, condensed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalFigures {
    /// `simulated-time`, `live` or `scripted-expert`.
    pub mode: String,
    /// First seed.
    pub first_seed: u64,
    /// Episodes.
    pub episodes: u64,
    /// Successes.
    pub successes: u64,
    /// Successes / episodes (0–1).
    pub success_rate: f64,
    /// 95 % Wilson interval (0–1).
    pub wilson_low: f64,
    /// 95 % Wilson interval (0–1).
    pub wilson_high: f64,
    /// Mean time to success over the successes (simulated s).
    pub mean_time_to_success_s: Option<f64>,
    /// Median time to success over the successes (s).
    pub median_time_to_success_s: Option<f64>,
    /// Inference latency per chunk (ms).
    pub inference_ms_p50: Option<f64>,
    /// Inference latency per chunk (ms).
    pub inference_ms_p99: Option<f64>,
    /// Live only: newest frame to first command (ms).
    pub e2e_ms_p50: Option<f64>,
    /// Wall time of the evaluation (s).
    pub wall_s: f64,
    /// A staged task (ALOHA's): per stage, the episodes that reached it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stages: Vec<scaledp_deploy::StageCount>,
    /// A bridged simulator's behaviour (its `scaledp-bridge` version: raised whenever the
    /// bridge changes in a way that can change an outcome); none from bridges before it was
    /// reported, and from the built-in simulator.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bridge: Option<String>,
    /// Every episode, in seed order: what the figures above are counted from.
    #[serde(default)]
    pub outcomes: Vec<crate::audit::Outcome>,
}

impl EvalFigures {
    /// From a full report.
    pub fn of(r: &scaledp_deploy::EvalReport) -> Self {
        let mut times: Vec<f64> = r
            .episodes
            .iter()
            .filter_map(|e| e.time_to_success_s)
            .collect();
        times.sort_by(f64::total_cmp);
        EvalFigures {
            mode: r.mode.clone(),
            first_seed: r.seed,
            episodes: r.episodes.len() as u64,
            successes: r.successes,
            success_rate: r.success_rate,
            wilson_low: r.wilson_95[0],
            wilson_high: r.wilson_95[1],
            mean_time_to_success_s: r.mean_time_to_success_s,
            median_time_to_success_s: scaledp_deploy::percentile(&times, 0.5),
            inference_ms_p50: r.inference_ms_p50,
            inference_ms_p99: r.inference_ms_p99,
            e2e_ms_p50: r.e2e_ms_p50,
            wall_s: r.wall_s,
            stages: r.stages.clone(),
            bridge: r
                .simulator
                .as_ref()
                .and_then(|s| s.get(BRIDGE_VERSION))
                .cloned(),
            outcomes: crate::audit::outcomes(r),
        }
    }

    /// A test fixture: `successes` of `episodes` in simulated time, interval 10–90 %, the
    /// first `successes` seeds the successful ones.
    #[cfg(test)]
    pub(crate) fn counts(successes: u64, episodes: u64) -> Self {
        let mut f = Self::pattern(&(0..episodes).map(|i| i < successes).collect::<Vec<_>>());
        // Impossible counts (more successes than episodes) stay as given, for the tests that
        // refuse them.
        f.successes = successes;
        f.success_rate = successes as f64 / episodes as f64;
        f
    }

    /// A test fixture: one episode per entry, successful where `true`, from the first test seed.
    #[cfg(test)]
    pub(crate) fn pattern(success: &[bool]) -> Self {
        let first_seed = scaledp_deploy::Split::Test.first_seed();
        let (episodes, successes) = (
            success.len() as u64,
            success.iter().filter(|s| **s).count() as u64,
        );
        EvalFigures {
            mode: "simulated-time".into(),
            first_seed,
            episodes,
            successes,
            success_rate: successes as f64 / episodes as f64,
            wilson_low: 0.1,
            wilson_high: 0.9,
            mean_time_to_success_s: None,
            median_time_to_success_s: None,
            inference_ms_p50: None,
            inference_ms_p99: None,
            e2e_ms_p50: None,
            wall_s: 1.0,
            stages: Vec::new(),
            bridge: None,
            outcomes: success
                .iter()
                .enumerate()
                .map(|(i, &success)| crate::audit::Outcome {
                    seed: first_seed + i as u64,
                    success,
                    highest_stage: None,
                    steps_to_success: success.then_some(100),
                    time_to_success_s: success.then_some(2.0),
                })
                .collect(),
        }
    }

    /// `34/50 (68 %, 54–79 %)`.
    pub fn cell(&self) -> String {
        format!(
            "{}/{} ({:.0} %, {:.0}–{:.0} %)",
            self.successes,
            self.episodes,
            100.0 * self.success_rate,
            100.0 * self.wilson_low,
            100.0 * self.wilson_high
        )
    }
}

/// A checkpoint's validation figure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValPoint {
    /// Optimizer steps of the checkpoint.
    pub step: u64,
    /// Successes on the validation seeds.
    pub successes: u64,
    /// Validation episodes.
    pub episodes: u64,
    /// Successes / episodes.
    pub success_rate: f64,
}

/// The controls of an arm, on the test seeds.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Controls {
    /// The untrained weights (the run's step-0 checkpoint).
    pub untrained: Option<EvalFigures>,
    /// The chosen checkpoint seeing only each episode's first camera frames.
    pub frozen_cameras: Option<EvalFigures>,
    /// The scripted teleoperator that recorded the demonstrations.
    pub scripted_expert: Option<EvalFigures>,
}

/// Where and what ran.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// The commit the binary that ran was built from ([`git_revision`]).
    pub git_revision: String,
    /// CPU model, cores, memory.
    pub machine: String,
    /// When the arm's result was written (UTC, RFC 3339).
    pub finished_utc: String,
}

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

/// The commit this binary was built from (`-dirty` when its tree had changes then, `unknown`
/// when built outside a git checkout): what ran, whatever the checkout says by the time a long
/// run finishes. Read at compile time; the crate is rebuilt when HEAD or the index moves.
pub fn git_revision() -> String {
    git_version::git_version!(
        args = ["--always", "--dirty=-dirty", "--abbrev=40", "--match=^$"],
        fallback = "unknown"
    )
    .to_string()
}

impl Provenance {
    /// This binary's revision, this machine, now.
    pub fn now() -> Self {
        Provenance {
            git_revision: git_revision(),
            machine: machine(),
            finished_utc: now_utc(),
        }
    }
}

/// Writes `value` as pretty JSON to `path` through a `.partial` file renamed over it, so an
/// interrupted write leaves the earlier file whole.
pub(crate) fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let mut partial = path.as_os_str().to_owned();
    partial.push(".partial");
    let partial = std::path::PathBuf::from(partial);
    std::fs::write(&partial, serde_json::to_vec_pretty(value)?)
        .with_context(|| format!("writing {}", partial.display()))?;
    std::fs::rename(&partial, path).with_context(|| format!("writing {}", path.display()))
}

/// The CPU model, core count and memory, from /proc.
pub fn machine() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|s| s.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mem = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("MemTotal"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or("? GiB".into(), |kb| format!("{:.0} GiB", kb / 1048576.0));
    format!("{cpu}, {cores} cores, {mem}")
}

/// Now as RFC 3339 UTC, to the second.
pub fn now_utc() -> String {
    humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string()
}

#[cfg(test)]
mod tests {
    /// A full commit hash (a tag in the history must not turn it into `git describe`'s
    /// `tag-N-gHASH`), `-dirty` at most, or `unknown` outside a checkout.
    #[test]
    fn the_revision_is_a_full_commit() {
        let r = super::git_revision();
        let hash = r.strip_suffix("-dirty").unwrap_or(&r);
        assert!(
            r == "unknown" || (hash.len() == 40 && hash.chars().all(|c| c.is_ascii_hexdigit())),
            "{r}"
        );
    }
}
