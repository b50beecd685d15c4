//! The simulated rig: a pick-and-place cell that a teleoperator, a scripted expert or a policy
//! drives through the same commands a real Cartesian controller takes, and whose cameras and
//! joint states come out over Zenoh like a real rig's.
//!
//! - [`World`] is the deterministic core: arms tracking `PoseStamped` TCP targets by
//!   damped-least-squares inverse kinematics ([`ik`]) at their joint-state rate (velocity and
//!   position limits enforced), grippers, and the task's cubes ([`task`]); `World::step(dt,
//!   commands)` advances it, no threads, no clock.
//! - [`ScriptedOperator`] demonstrates the task as a teleoperator would: leader samples (TCP
//!   pose + gripper opening) at 100 Hz with human-like noise, reading the task's privileged
//!   state as a person looking at the table would.
//! - [`SimOptions`] → [`SimOptions::spawn`] → [`Sim`] runs the world in real time and publishes
//!   the rig's cameras and joint states exactly as zenoh-bridge-ros2dds does (key = topic without
//!   its leading `/`, payload = CDR with its encapsulation header) or as rmw_zenoh does
//!   (domain/topic/type/hash keys with attachments); it takes commands on the rig's command
//!   topics, resets on `scaledp/sim/reset` and reports the task on `scaledp/sim/task`. For a
//!   rig that lists them it publishes as realsense2_camera and the ZED wrapper do: registered
//!   depth in the rig's encoding ([`depth`]), `camera_info` with the renderer's pinhole K, `/tf`
//!   at the rig's rate and `/tf_static` once, served to late joiners from a cache the way
//!   zenoh-bridge-ros2dds or rmw_zenoh serve it ([`tf`], [`LatchedCache`]).
//! - [`synth::write_episode`] writes the operator's episode straight to an MCAP file, faster than
//!   real time and byte-reproducible; [`headless::run_episode`] scores it without rendering.
//!
//! Stamps: `header.stamp` is the capture time; a message leaves later by a realistic latency
//! (cameras tens of ms, arms well under one ms), both with seeded jitter. Everything but the
//! wall-clock origin and, live, the timing of threads is fixed by the seed.

pub mod bridge;
pub mod depth;
mod error;
pub mod headless;
pub mod ik;
pub mod key_style;
mod latched;
pub mod messages;
pub mod operator;
pub mod pedal;
pub mod render;
mod runtime;
pub mod scene;
mod streams;
pub mod synth;
pub mod task;
pub mod tf;
mod video;
pub mod world;

pub use error::{Error, Result};
pub use headless::{run_episode, EpisodeResult, OfflineRun};
pub use key_style::KeyStyle;
pub use latched::LatchedCache;
pub use operator::{ScriptedOperator, LEADER_RATE_HZ};
pub use pedal::{EpisodeLine, Pedal};
pub use runtime::{PublishHook, Sim, SimOptions};
pub use scene::Scene;
pub use synth::write_episode;
pub use task::{CubeState, TaskState, SUCCESS_RADIUS_M};
pub use world::{ArmCommand, ArmState, World, WorldState};
