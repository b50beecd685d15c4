//! Scoring a run of simulated episodes: successes, mean durations, the Wilson interval.

use scaledp_sim::TaskState;

/// Successes and times over a run of episodes.
#[derive(Debug, Default)]
pub struct Successes {
    /// Episodes counted.
    pub episodes: u64,
    /// Of which successes.
    pub successes: u64,
    duration_s: f64,
    time_to_success_s: f64,
}

impl Successes {
    /// Counts one episode that ended in `task` after `duration_s`.
    pub fn add(&mut self, task: &TaskState, duration_s: f64) {
        self.episodes += 1;
        self.duration_s += duration_s;
        if task.success {
            self.successes += 1;
            self.time_to_success_s += task.time_to_success_s.unwrap_or(duration_s);
        }
    }
    /// Success rate (0 without episodes).
    pub fn rate(&self) -> f64 {
        self.successes as f64 / self.episodes.max(1) as f64
    }
    /// Mean episode duration (s).
    pub fn mean_duration_s(&self) -> f64 {
        self.duration_s / self.episodes.max(1) as f64
    }
    /// Mean time to success over the successes (s).
    pub fn mean_time_to_success_s(&self) -> f64 {
        self.time_to_success_s / self.successes.max(1) as f64
    }
}

/// The 95 % Wilson score interval (one definition, shared with `scaledp eval`).
pub use scaledp_deploy::wilson_interval;
