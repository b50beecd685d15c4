//! The converter: MCAP recordings, ros2 MCAP files, rosbag2 directories (mcap or sqlite3) and
//! ROS 1 bags → LeRobot v3.0 datasets with time-aligned frames, resized JPEG images, proprio
//! state and 6D end-effector pose actions computed by forward kinematics.

mod error;
pub mod source;

pub use error::{Error, Result};
pub use source::{RawMessage, Recording, Serialization, TopicInfo};
