//! The converter: MCAP recordings, ros2 MCAP files, rosbag2 directories (mcap or sqlite3) and
//! ROS 1 bags → LeRobot v3.0 datasets with time-aligned frames, resized JPEG images, proprio
//! state and 6D end-effector pose actions computed by forward kinematics.

pub mod align;
mod batch;
mod decode;
mod detect;
mod encode_pool;
pub mod episode;
mod error;
pub mod frames;
#[cfg(test)]
mod fuzz;
pub mod images;
mod kinematics;
pub mod lerobot;
pub mod live;
mod lz4;
mod mcap_source;
mod mcap_stream;
mod prefetch;
mod resample;
pub mod ros1;
mod rosbag2;
mod series;
pub mod source;
pub mod stats;
pub mod urdf;

pub use batch::{
    collect_inputs, content_hash, merge, read_input, run, shard, JobOptions, Outcome, Progress,
};
pub use episode::{ConvertOptions, Episode};
pub use error::{Error, Result};
pub use mcap_source::read_mcap;
pub use ros1::read_ros1_bag;
pub use rosbag2::read_rosbag2;
pub use source::{RawMessage, Recording, Serialization, TopicInfo};
