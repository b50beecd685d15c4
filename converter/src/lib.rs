//! The converter: MCAP recordings, ros2 MCAP files, rosbag2 directories (mcap or sqlite3) and
//! ROS 1 bags → LeRobot v3.0 datasets with time-aligned frames, resized JPEG images, proprio
//! state and 6D end-effector pose actions computed by forward kinematics.
//!
//! # The API
//!
//! - **A batch job**: [`collect_inputs`] expands paths into inputs, [`run`] converts them into
//!   a dataset ([`JobOptions`], [`Progress`] events, one [`InputResult`] per input), [`merge`]
//!   joins datasets, [`shard`] and [`content_hash`] are what `--shard` and resuming use.
//! - **Object storage**: [`collect`] expands local paths and `s3://` [`Location`]s into
//!   [`Input`]s, [`run_inputs`] converts them into a dataset at a path or URL (ranged reads of
//!   MCAP objects, a staged upload published with `meta/info.json` last), [`merge_datasets`]
//!   joins datasets anywhere ([`MergeOptions`]).
//! - [`floor`] is the converter's floor on a machine (what `bench convert` compares with).
//! - **One input**: [`read_input`] (or [`read_mcap`], [`read_ros1_bag`], [`read_rosbag2`])
//!   reads a [`Recording`]; [`convert`] turns it into an [`Episode`] with [`ConvertOptions`],
//!   its frames from a [`FrameStore`] ([`InMemory`] for a recording read whole).
//! - **What a dataset records**: [`Sidecar`] (`meta/scaledp.json`) and its [`EpisodeRecord`]s
//!   with their [`Stats`] and [`AlignmentReport`]; [`align`] is the alignment itself.
//! - **A deployment node** builds its observations with [`live`]: the same frame pick rule,
//!   joint interpolation, kinematics ([`live::ArmKinematics`], on [`UrdfChain`]s for URDF rigs)
//!   and image path ([`images`]) as the converter, so a policy sees at run time what it was
//!   trained on.
//! - [`ros1::decode`] reads the ROS 1 serialization of the message types the converter uses.
//!
//! Every error is an [`Error`] naming the file and what is wrong with it.

mod actions;
/// The alignment rules (their own crate: the recorder's verdict applies the same ones).
pub use scaledp_align as align;
mod batch;
mod camera_info;
mod cameras;
mod decode;
pub mod depth;
mod destination;
mod detect;
mod encode_pool;
mod floor;
// Public only for the paths callers used before the re-exports below
// (`scaledp_converter::episode::convert` in sim/tests): use the crate root.
#[doc(hidden)]
pub mod episode;
mod error;
// Public only for old paths (sim/tests) and the prefetch test's diagnostics.
#[doc(hidden)]
pub mod frames;
#[cfg(test)]
mod fuzz;
pub mod images;
mod inputs;
mod kinematics;
mod labels;
mod lerobot;
pub mod live;
mod lz4;
mod mcap_remote;
mod mcap_source;
mod mcap_stream;
mod merge;
mod objects;
mod options;
mod per_input;
mod prefetch;
mod raw_rows;
mod recorded;
mod resample;
pub mod ros1;
mod rosbag2;
mod series;
mod source;
mod stats;
mod summary;
mod urdf;
mod video;

pub use align::{align, Alignment, AlignmentReport, Stream, StreamReport};
pub use batch::{run, run_inputs, InputResult, Progress};
pub use camera_info::Intrinsics;
pub use episode::{convert, state_names, CameraFrames, DepthFrames, Episode};
pub use error::{Error, Result};
pub use floor::{floor, FloorReport};
pub use frames::{FrameKey, FrameStore, InMemory};
pub use inputs::{collect_inputs, content_hash, read_input, shard};
pub use lerobot::{CameraIntrinsics, DepthFeature, EpisodeRecord, Sidecar};
pub use mcap_source::read_mcap;
pub use merge::{merge, merge_datasets, MergeOptions, MergeSummary};
pub use objects::{collect, Input, ObjectInput};
pub use options::{ConvertOptions, JobOptions, Unlabeled};
pub use recorded::{Recorded, Verdict, VERDICT_RECORD};
pub use ros1::read_ros1_bag;
pub use rosbag2::read_rosbag2;
pub use scaledp_codec::Codec as VideoCodec;
pub use scaledp_store::{Location, ObjectUrl};
pub use source::{RawMessage, Recording, Serialization, TopicInfo};
pub use stats::Stats;
pub use summary::{mcap_summary, McapSummary};
pub use urdf::UrdfChain;
