//! What an evaluation is condensed to in a results file: the figures with every episode's
//! outcome, a checkpoint's validation point, and the controls.

use serde::{Deserialize, Serialize};

use crate::audit::Outcome;

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
    pub outcomes: Vec<Outcome>,
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

    /// No episodes: a figure to fill in (pooled counts).
    pub fn empty() -> Self {
        EvalFigures {
            mode: "simulated-time".into(),
            first_seed: 0,
            episodes: 0,
            successes: 0,
            success_rate: 0.0,
            wilson_low: 0.0,
            wilson_high: 1.0,
            mean_time_to_success_s: None,
            median_time_to_success_s: None,
            inference_ms_p50: None,
            inference_ms_p99: None,
            e2e_ms_p50: None,
            wall_s: 0.0,
            stages: Vec::new(),
            bridge: None,
            outcomes: Vec::new(),
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
                .map(|(i, &success)| Outcome {
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
