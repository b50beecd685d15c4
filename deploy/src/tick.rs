//! What one control tick hands out: a window to predict on, and per-arm commands.

use glam::DMat4;
use scaledp_policy::Observation;

use crate::safety::Clamped;

/// Ask the policy for a chunk on this window; hand the chunk back to [`Controller::install`]
/// with `index`.
#[derive(Debug, Clone)]
pub struct Request {
    /// The tick the window ends at.
    pub index: u64,
    /// The window.
    pub observation: Observation,
}

/// One control tick's bookkeeping.
#[derive(Debug, Clone)]
pub struct Tick {
    /// Tick number since the start (or the last reset).
    pub index: u64,
    /// The observation instant (ns, stamp clock).
    pub obs_ns: u64,
    /// Why this tick has no observation (a stream is silent, a frame stale…).
    pub halted: Option<String>,
    /// A chunk to compute.
    pub request: Option<Request>,
}

/// One arm's command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Command {
    /// Arm index (rig order).
    pub arm: usize,
    /// TCP target, `base_from_tcp`, clamped.
    pub base_from_tcp: DMat4,
    /// Gripper opening (m), clamped; `None` for an arm without gripper.
    pub gripper_width_m: Option<f64>,
    /// What was clamped.
    pub clamped: Clamped,
}
