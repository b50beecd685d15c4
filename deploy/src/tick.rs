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
#[derive(Debug, Clone, PartialEq)]
pub struct Command {
    /// Arm index (rig order).
    pub arm: usize,
    /// TCP target, `base_from_tcp`, clamped (for a joint action, the TCP its joints reach).
    pub base_from_tcp: DMat4,
    /// Joint targets (rad, rig order), clamped, for an arm whose command topic takes a leader
    /// arm's `JointState`; `None` for an arm taking TCP targets.
    pub joints: Option<Vec<f64>>,
    /// Gripper opening (m), clamped; `None` for an arm without gripper.
    pub gripper_width_m: Option<f64>,
    /// What was clamped.
    pub clamped: Clamped,
}

impl From<&Command> for scaledp_sim::ArmCommand {
    /// What the simulator takes: the joints for an arm commanded in joints, else the TCP.
    fn from(c: &Command) -> Self {
        scaledp_sim::ArmCommand {
            pose: c.joints.is_none().then_some(c.base_from_tcp),
            joints: c.joints.clone(),
            gripper_width_m: c.gripper_width_m,
        }
    }
}
