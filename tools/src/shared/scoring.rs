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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wilson_intervals_match_the_textbook() {
        // 80 of 100: 71.1–86.7 %; 100 of 100: 96.3–100 %.
        let (lo, hi) = wilson_interval(80, 100);
        assert!(
            (lo - 0.7112).abs() < 1e-3 && (hi - 0.8666).abs() < 1e-3,
            "{lo} {hi}"
        );
        let (lo, hi) = wilson_interval(100, 100);
        assert!((lo - 0.9630).abs() < 1e-3 && hi == 1.0, "{lo} {hi}");
    }
}
