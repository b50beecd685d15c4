//! Recordings, ROS bags, LeRobot datasets, training curves and policy rollouts as
//! [rerun](https://rerun.io) streams: what `scaledp view` shows, and the live views of
//! `record --view`, `train --view`, `eval --view` and `predict --view`.
//!
//! ```no_run
//! # fn main() -> scaledp_viewer::Result<()> {
//! use scaledp_viewer::{view, Target, ViewOptions};
//! let summary = view(
//!     &["demos/episode_000000.mcap".to_string(), "datasets/cups".to_string()],
//!     ViewOptions::new().max_width(Some(640)),
//!     &Target::Save("cups.rrd".into()),
//! )?;
//! println!("{} episodes in {:?}", summary.shown.len(), summary.saved);
//! # Ok(()) }
//! ```
//!
//! Every episode is its own rerun recording (application id `scaledp`, named after the file,
//! or `<dataset>/episode_NNNNNN`). Inside one, entity paths are:
//!
//! | path | what | when |
//! |---|---|---|
//! | `cameras/<camera>` | every frame (recordings), every stored frame (datasets) | per frame |
//! | `depth/<camera>` | the camera's registered depth (`DepthImage`, meter 1000 for mm, 1 for m) | per frame |
//! | `world/tf/<frame>` | a tf frame placed by its transform from its parent (`/tf`, `/tf_static`), with axes; a tree's root tied to `world` | per message / static |
//! | `joints/<arm>` | measured joint positions, one series per joint | per message |
//! | `gripper/<arm>` | measured gripper opening (m) | per message |
//! | `topics/<topic>` | joint states of topics no arm of the rig reads | per message |
//! | `pose/<arm>/<x\|y\|z\|roll\|pitch\|yaw\|gripper>` | two series, `state` and `action` (TCP space) | per frame |
//! | `joint_space/<arm>/<joint\|gripper>` | two series, `state` and `action` (joint space) | per frame |
//! | `world/<arm>` | the arm's base (arms side by side, 0.8 m apart) | static |
//! | `world/<arm>/chain` | the kinematic chain through the joint origins | per frame |
//! | `world/<arm>/links/<k>`, `world/<arm>/tcp` | link frames and the TCP (the pose in `state`) | per frame |
//! | `world/<arm>/tcp_trajectory` | the TCP over the whole episode | static |
//! | `world/<arm>/action_chunk` | the next 16 actions' positions | per frame |
//! | `world/<arm>/predicted_chunk` | a policy's predicted chunk ([`RolloutView`]) | per prediction |
//! | `quality/camera_skew_ms`, `quality/invalid_ticks`, `quality/gaps` | the converter's alignment signals (recordings) | per tick / gap |
//! | `log` | episode metadata (task, operator, outcome, drops), warnings, gaps | text |
//!
//! Timelines: recordings have `capture_time` (header stamps; every message and tick),
//! `receive_time` (messages only) and `tick` (the converter's aligned ticks); datasets
//! `frame_index` and `timestamp`; training `step`; rollouts `step` and `timestamp`.
//!
//! Recordings are shown twice over: every message as recorded, and the episode exactly as
//! `scaledp convert` would make it (the converter's own alignment and state/action code, run
//! without decoding a pixel), so what is plotted is what a dataset would hold. MCAP files are
//! read forward once with memory bounded by one chunk; bags are read whole.

mod arm;
mod columns;
mod dataset;
mod depth;
mod episode;
mod error;
mod images;
mod input;
mod layout;
mod live;
mod mcap_read;
mod recording;
mod runs;
mod session;
mod sink;
mod space;
mod ticks;

pub use episode::Prediction;
pub use error::{Error, Result};
pub use input::{classify, InputKind};
pub use live::{LiveOptions, RecordView, TopicFigures};
pub use runs::{RolloutView, TrainingView};
pub use session::{view, Shown, Summary, ViewOptions, Viewer};
pub use sink::{Target, APPLICATION_ID};
