//! What a serving node's threads share: the status it reports, the inputs its subscribers hand
//! to the control loop, the hook that sees each tick's commands, and a lock that survives a
//! panicked holder.

use std::sync::{Arc, Mutex};

use scaledp_schema::msg::JointState;
use serde::Serialize;

use crate::controller::Command;

/// Called with the tick index and the commands of every tick that has some.
pub type CommandHook = Arc<dyn Fn(u64, &[Command]) + Send + Sync>;

/// What a serving node is doing (its status key's JSON).
#[derive(Debug, Clone, Default, Serialize)]
pub struct Status {
    /// Control ticks so far.
    pub ticks: u64,
    /// Ticks with commands (published, or printed with `--dry-run`).
    pub commanded_ticks: u64,
    /// Ticks with a clamped command.
    pub clamped_ticks: u64,
    /// Ticks stopped on stale or missing observations.
    pub halted_ticks: u64,
    /// Chunks predicted.
    pub chunks: u64,
    /// Commanded ticks per second over the last two seconds.
    pub command_rate_hz: f64,
    /// Inference latency (ms): median and 99th percentile.
    pub inference_ms_p50: Option<f64>,
    /// See `inference_ms_p50`.
    pub inference_ms_p99: Option<f64>,
    /// End-to-end latency (ms): from the newest camera frame received when a window was taken
    /// to the first command published from that window's chunk; median and 99th percentile.
    pub e2e_ms_p50: Option<f64>,
    /// See `e2e_ms_p50`.
    pub e2e_ms_p99: Option<f64>,
    /// Why the last tick had no command, if it had none.
    pub holding: Option<String>,
    /// Nothing is published.
    pub dry_run: bool,
}

impl Status {
    /// The one-line form.
    pub fn line(&self) -> String {
        let ms = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.0}"));
        format!(
            "{:.1} cmd/s, inference p50 {} ms p99 {} ms, frame→command p50 {} ms, {} chunks, {} ticks ({} clamped, {} halted){}{}",
            self.command_rate_hz,
            ms(self.inference_ms_p50),
            ms(self.inference_ms_p99),
            ms(self.e2e_ms_p50),
            self.chunks,
            self.ticks,
            self.clamped_ticks,
            self.halted_ticks,
            if self.dry_run { ", dry run" } else { "" },
            self.holding.as_ref().map_or(String::new(), |h| format!(" — holding: {h}"))
        )
    }
}

pub(crate) enum Input {
    Image(usize, u64, u64, Vec<u8>),
    Joints(usize, bool, u64, JointState),
    /// A simulation's `/clock` (ns).
    Clock(u64),
}

pub(crate) fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}
