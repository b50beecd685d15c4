//! What every input format (our MCAP recordings, any ros2 MCAP, rosbag2 with mcap or sqlite3
//! storage, ROS 1 bags) is read into: raw messages with their topic, type and serialization.

use std::collections::BTreeMap;

/// How a message's bytes are serialized.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Serialization {
    /// ROS 2 CDR, with the 4-byte encapsulation header (MCAP `cdr`, rosbag2 `cdr`).
    Cdr,
    /// ROS 1 serialization (no header; `std_msgs/Header` carries a `seq`).
    Ros1,
}

/// One message as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct RawMessage {
    /// Topic name with its leading `/`.
    pub topic: String,
    /// Type in ROS 2 form, `pkg/msg/Type` (ROS 1 `pkg/Type` is rewritten to this).
    pub message_type: String,
    /// When it was recorded (ns since the epoch).
    pub log_time_ns: u64,
    /// The serialized message.
    pub data: Vec<u8>,
    /// How `data` is serialized.
    pub serialization: Serialization,
}

/// One topic of an input.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicInfo {
    /// Topic name with its leading `/`.
    pub topic: String,
    /// Type in ROS 2 form, `pkg/msg/Type`.
    pub message_type: String,
    /// Number of messages, when the input's index says.
    pub count: Option<u64>,
}

/// A whole input read into memory: topics, messages in log-time order, and metadata records
/// (MCAP metadata by name; empty for bags).
#[derive(Debug, Clone, Default)]
pub struct Recording {
    /// Topics, sorted by name.
    pub topics: Vec<TopicInfo>,
    /// Messages of the topics asked for, sorted by log time.
    pub messages: Vec<RawMessage>,
    /// Metadata records by name.
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
}

/// Whether the converter reads messages of this type (cameras, joint states, pose commands,
/// camera intrinsics):
/// a channel of one must be `cdr`-encoded.
pub(crate) fn is_read(message_type: &str) -> bool {
    matches!(
        message_type,
        "sensor_msgs/msg/Image"
            | "sensor_msgs/msg/CompressedImage"
            | "foxglove_msgs/msg/CompressedVideo"
            | "sensor_msgs/msg/JointState"
            | "geometry_msgs/msg/PoseStamped"
            | "sensor_msgs/msg/CameraInfo"
    )
}

/// `sensor_msgs/Image` → `sensor_msgs/msg/Image`; ROS 2 names pass through.
pub fn ros2_type_name(name: &str) -> String {
    let parts: Vec<&str> = name.split('/').collect();
    match parts.as_slice() {
        [pkg, ty] => format!("{pkg}/msg/{ty}"),
        _ => name.to_string(),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn type_names() {
        assert_eq!(
            super::ros2_type_name("sensor_msgs/Image"),
            "sensor_msgs/msg/Image"
        );
        assert_eq!(
            super::ros2_type_name("sensor_msgs/msg/Image"),
            "sensor_msgs/msg/Image"
        );
    }
}
