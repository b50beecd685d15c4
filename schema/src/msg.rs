//! The ROS 2 messages scaledp reads and writes, with CDR encoding and their `ros2msg` definitions.
//!
//! Definitions are composed the way rosbag2 (and Python `rosbags`) write them into MCAP schemas:
//! the root `.msg` text, then each dependency depth-first in declaration order, deduplicated, each
//! introduced by a line of 80 `=` and `MSG: pkg/Type`. A type scaledp has no definition for is
//! looked up as a `.msg` file ([`MsgSearch`]), the way rosbag2 does it.
//!
//! - [`Image`], [`CompressedImage`], [`CompressedVideo`] (camera streams, [`image_layout`]);
//! - [`JointState`], [`CameraInfo`] with [`RegionOfInterest`] (`sensor_msgs`);
//! - [`Point`], [`Quaternion`], [`Pose`], [`PoseStamped`], [`Vector3`], [`Transform`],
//!   [`TransformStamped`] (`geometry_msgs`) and [`TfMessage`] (`/tf`, `/tf_static`);
//! - [`Time`], [`Header`], [`Clock`].

mod base;
mod geometry;
mod image;
mod lookup;
mod sensor;
mod stamp;
#[cfg(test)]
mod tests;
mod texts;

pub use base::{header_stamp, Clock, Header, RosMessage, Time};
pub use geometry::{
    Point, Pose, PoseStamped, Quaternion, TfMessage, Transform, TransformStamped, Vector3,
};
pub use image::{image_layout, is_keyframe, CompressedImage, CompressedVideo, Image, ImageLayout};
pub use lookup::MsgSearch;
pub use sensor::{camera_info_size, CameraInfo, JointState, RegionOfInterest};
pub use stamp::StampField;
pub use texts::{definition, known_types};
