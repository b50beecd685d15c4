//! The controller's settings.

use crate::safety::Workspace;

/// How the controller acts.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlOptions {
    /// Actions executed per chunk (diffusion_policy's action horizon), 1 … C.
    pub action_steps: usize,
    /// Workspace box per arm; `None`: [`Workspace::for_rig`].
    pub workspace: Option<Vec<Workspace>>,
    /// Largest TCP translation per tick (m).
    pub max_step_m: f64,
    /// Largest TCP rotation per tick (rad).
    pub max_step_rad: f64,
    /// A stream silent for more than this many of its periods stops the commands.
    pub stale_periods: f64,
    /// …but never for less than this (s): a 1 kHz arm's two periods are shorter than a busy
    /// machine's scheduling jitter.
    pub min_silence_s: f64,
    /// The converter's frame freshness rule (`--stale-periods`, 1.5).
    pub frame_stale_periods: f64,
    /// The observation tick runs this far behind the receive clock (s), so that joints have a
    /// sample after it and the tick's camera frames (tens of ms in flight) have arrived; never
    /// less than 1.5 periods of the slowest joint or gripper stream.
    pub obs_lag_s: f64,
    /// A control for evaluations: every observation shows the cameras' first frames of the
    /// episode (the state stays live), so a policy that succeeds anyway is not using vision.
    pub freeze_cameras: bool,
    /// Every stream's sample for a tick is delivered before the tick (a simulator stepped in
    /// lockstep): the observation is taken at the tick itself, as the converter aligned the
    /// training data, and `obs_lag_s` is ignored.
    pub lockstep: bool,
}

impl Default for ControlOptions {
    fn default() -> Self {
        ControlOptions {
            action_steps: 8,
            workspace: None,
            max_step_m: 0.05,
            max_step_rad: 0.25,
            stale_periods: 2.0,
            min_silence_s: 0.05,
            frame_stale_periods: 1.5,
            obs_lag_s: 0.05,
            freeze_cameras: false,
            lockstep: false,
        }
    }
}
