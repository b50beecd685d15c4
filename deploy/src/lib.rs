//! Closing the loop: a trained ScaleDP checkpoint driving a rig, and its success rate measured.
//!
//! - [`Controller`] is the pure, clock-free core: stamped frames and joint states in, at each
//!   control tick the observation window built exactly as `scaledp convert` built the training
//!   data, a receding-horizon plan of the policy's chunks, and per-arm commands out (a TCP
//!   target in the base frame and a gripper opening), clamped to a workspace box and a maximum
//!   step per tick ([`safety`]); a stream silent for more than two periods stops the commands.
//! - [`serve`] runs the core on Zenoh (zenoh-bridge-ros2dds or rmw_zenoh keys, as the recorder
//!   and the simulator use them) with inference on its own thread, overlapping execution.
//! - [`eval`] runs seeded episodes of the simulated task in simulated time — the world stepped,
//!   the cameras rendered and the same core called synchronously — and reports the success
//!   rate with its 95 % Wilson interval ([`stats`]); [`live`] runs the simulator and [`serve`]
//!   over loopback Zenoh in real time instead. Seeds come in fixed ranges ([`Split`]): the
//!   demonstrations' (0 …), validation (1 000 000 …, to choose checkpoints and tune),
//!   development (2 000 000 …, the old test range that pilots saw) and test (3 000 000 …, what
//!   is reported). [`run_expert`] scores the scripted teleoperator on the
//!   same seeds (the ceiling control); [`ControlOptions::freeze_cameras`] the vision control.
//! - Rigs whose simulator runs behind the bridge protocol (`metaworld/<task>`) are evaluated
//!   the same way, the simulator stepped once per control tick ([`run_eval`] dispatches).
//! - [`check`] refuses, in one line and before anything moves, a checkpoint for another rig or
//!   a rig lacking the checkpoint's cameras or dimensions.

mod bridge_eval;
pub mod check;
mod command;
pub mod controller;
mod error;
pub mod eval;
mod expert;
mod inputs;
pub mod live;
mod options;
mod recording;
mod report;
pub mod safety;
pub mod serve;
pub mod stats;
mod streams;
mod tick;

pub use controller::{Command, ControlOptions, Controller, Request, Tick};
pub use error::{Error, Result};
pub use eval::{run_eval, EpisodeReport, EvalOptions, EvalReport, Split};
pub use expert::run_expert;
pub use live::run_live;
pub use recording::task_text;
pub use safety::{Limits, Workspace};
pub use serve::{ServeOptions, Server, Status};
pub use stats::{percentile, stage_counts, wilson_interval, StageCount};
