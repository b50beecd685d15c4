//! Raw messages → typed ROS messages, whatever their serialization.

use std::path::Path;

use scaledp_schema::msg::{CompressedImage, Image, JointState, PoseStamped};
use scaledp_schema::RosMessage;

use crate::error::{Error, Result};
use crate::source::{RawMessage, Serialization};

fn wrap<T>(path: &Path, m: &RawMessage, r: std::result::Result<T, String>) -> Result<T> {
    r.map_err(|reason| Error::Message {
        path: path.into(),
        topic: m.topic.clone(),
        log_time_ns: m.log_time_ns,
        reason,
    })
}

fn text<T>(r: std::result::Result<T, impl std::fmt::Display>) -> std::result::Result<T, String> {
    r.map_err(|e| e.to_string())
}

/// A camera frame: raw or compressed.
#[derive(Debug, Clone)]
pub enum Frame {
    /// `sensor_msgs/Image`.
    Raw(Image),
    /// `sensor_msgs/CompressedImage`.
    Compressed(CompressedImage),
}

/// Decodes an image message (raw or compressed) from `path`.
pub fn frame(path: &Path, m: &RawMessage) -> Result<Frame> {
    if crate::video::is_video(&m.message_type) {
        // Video frames decode in stream order, which only the MCAP read does (crate::video);
        // bags are read whole into memory, where decoded video would not fit, and the live
        // controller decodes only the frames it picks.
        let reason = "a CompressedVideo camera frame on its own: video topics are decoded \
                      in stream order when `convert` reads an .mcap file (pass a rosbag2 \
                      bag's .mcap files themselves), not from bags read into memory nor live \
                      by serve/eval (publish raw or JPEG images to a policy)";
        return wrap(path, m, Err(reason.to_string()));
    }
    let compressed = m.message_type.ends_with("/CompressedImage");
    let r = match (m.serialization, compressed) {
        (Serialization::Cdr, false) => Image::from_cdr(&m.data)
            .map(Frame::Raw)
            .map_err(|e| e.to_string()),
        (Serialization::Cdr, true) => CompressedImage::from_cdr(&m.data)
            .map(Frame::Compressed)
            .map_err(|e| e.to_string()),
        (Serialization::Ros1, false) => text(crate::ros1::decode::image(&m.data).map(Frame::Raw)),
        (Serialization::Ros1, true) => {
            text(crate::ros1::decode::compressed_image(&m.data).map(Frame::Compressed))
        }
    };
    wrap(path, m, r)
}

/// Decodes a `sensor_msgs/JointState`.
pub fn joint_state(path: &Path, m: &RawMessage) -> Result<JointState> {
    let r = match m.serialization {
        Serialization::Cdr => JointState::from_cdr(&m.data).map_err(|e| e.to_string()),
        Serialization::Ros1 => text(crate::ros1::decode::joint_state(&m.data)),
    };
    wrap(path, m, r)
}

/// Decodes a `geometry_msgs/PoseStamped`.
pub fn pose_stamped(path: &Path, m: &RawMessage) -> Result<PoseStamped> {
    let r = match m.serialization {
        Serialization::Cdr => PoseStamped::from_cdr(&m.data).map_err(|e| e.to_string()),
        Serialization::Ros1 => text(crate::ros1::decode::pose_stamped(&m.data)),
    };
    wrap(path, m, r)
}
