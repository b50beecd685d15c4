//! The teleop recorder: subscribes over Zenoh to every topic of a rig (as zenoh-bridge-ros2dds
//! or rmw_zenoh publish them: CDR-encoded ROS 2 messages) and writes one crash-safe, ROS
//! 2-profile MCAP file per episode.
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
//! What is recorded: the training streams (colour, joints, grippers, commands) and what the rig
//! keeps beside them (registered depth, `camera_info`, `/tf`, `/tf_static`, further topics),
//! verbatim, each with the `ros2msg` schema of its type: scaledp's own, else the `.msg` files
//! under `AMENT_PREFIX_PATH` and `--msg-path` ([`scaledp_schema::msg::MsgSearch`]), else an
//! empty one (and a warning). [`TopicPattern`]s add topics by name or glob. Latched topics are
//! fetched from their publishers' caches when the recorder joins late (see `subscribe`) and
//! written at the start of every episode.
//!
//! Episodes are written as `episode_NNNNNN.mcap.partial`, flushed (a closed chunk) at least every
//! second, and renamed to `episode_NNNNNN.mcap` when they end; [`recover`] repairs a `.partial`
//! left by a crash. Every message the queue had to drop is counted per topic and stored in the
//! episode's `scaledp.episode` metadata record, with link outages and what the recorder noticed
//! (depth in an undeclared encoding, a `camera_info` of another size, no `/tf_static`).

mod channels;
mod checks;
mod control;
mod disk;
mod episode;
mod error;
mod intake;
mod judge;
pub mod keys;
mod latched;
mod links;
mod liveness;
pub mod net;
mod options;
mod patterns;
mod pilot;
mod recover;
mod report;
mod session;
mod state;
mod subscribe;
mod verdict;
mod writer;

pub use control::{Command, Label, CONTROL_WORDS};
pub use disk::{DiskStatus, FreeSpace, DEFAULT_EPISODE_S};
pub use episode::{
    partial_path, ChannelSpec, Compression, EpisodeOptions, EpisodeSummary, EpisodeWriter,
    OFFERED_QOS_LATCHED_YAML, OFFERED_QOS_YAML,
};
pub use error::{Error, Result};
pub use intake::Control;
pub use liveness::{LiveState, Liveness, TopicLive, SLOW_FRACTION};
pub use options::RecorderOptions;
pub use patterns::{parse_message_type, TopicPattern};
pub use pilot::{Phase, Pilot, Plan};
pub use recover::{default_output, recover, RecoverySummary};
pub use report::{EpisodeReport, Event, Status, TopicStatus};
pub use session::Recorder;
pub use state::now_ns;
pub use verdict::{TopicVerdict, Verdict, STARTED_WITH_MISSING_TOPICS, VERDICT_RECORD};
pub use writer::episode_file_name;
