//! The teleop recorder: subscribes over Zenoh to a rig's camera and joint-state topics (as
//! zenoh-bridge-ros2dds or rmw_zenoh publish them: CDR-encoded ROS 2 messages) and writes one
//! crash-safe, ROS 2-profile MCAP file per episode.
//!
//! ```no_run
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! use scaledp_recorder::{net, Command, Label, RecorderOptions};
//! let rig = scaledp_schema::Rig::builtin("franka_2zed").expect("shipped rig");
//! let config = net::zenoh_config(None, &[], &[])?;
//! let recorder = RecorderOptions::new(rig, "demos").task("stack the cups").start(config)?;
//! recorder.send(Command::Start);
//! std::thread::sleep(std::time::Duration::from_secs(10));
//! recorder.send(Command::Stop(Label::Success));
//! recorder.finish()?;
//! # Ok(()) }
//! ```
//!
//! Episodes are written as `episode_NNNNNN.mcap.partial`, flushed (a closed chunk) at least every
//! second, and renamed to `episode_NNNNNN.mcap` when they end; [`recover`] repairs a `.partial`
//! left by a crash. Every message the queue had to drop is counted per topic and stored in the
//! episode's `scaledp.episode` metadata record.

mod control;
mod episode;
mod error;
pub mod keys;
pub mod net;
mod recover;
mod session;
mod writer;

pub use control::{Command, Label};
pub use episode::{
    partial_path, Compression, EpisodeOptions, EpisodeSummary, EpisodeWriter, OFFERED_QOS_YAML,
};
pub use error::{Error, Result};
pub use recover::{default_output, recover, RecoverySummary};
pub use session::{
    now_ns, Control, EpisodeReport, Event, Recorder, RecorderOptions, Status, TopicStatus,
};
pub use writer::episode_file_name;
