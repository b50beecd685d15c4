//! Every topic a rig publishes, as the recorder subscribes to them and the converter and the
//! session verdict read them: colour images and joints (what a policy trains on), the command
//! topics, and what a serious recording keeps beside them (registered depth, `camera_info`,
//! `/tf`, `/tf_static` and any further topics the rig lists).

use serde::{Deserialize, Serialize};

/// One topic a rig publishes, with its type and nominal rate.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicSpec {
    /// ROS 2 topic name with its leading `/`.
    pub topic: String,
    /// Full ROS 2 type, e.g. `sensor_msgs/msg/JointState`.
    pub message_type: String,
    /// Nominal publish rate (Hz); 0 where the rig expects none (latched topics, further topics
    /// listed without a rate), so no rate is checked.
    pub rate_hz: f64,
    /// True for image topics (large messages).
    pub is_image: bool,
    /// What the topic is to the rig.
    pub kind: TopicKind,
    /// The camera or arm it belongs to (empty for rig-wide topics).
    pub owner: String,
    /// Transient-local ("latched"): published once and re-delivered to late joiners, so a
    /// recorder must query the publishers' cache, and every episode must hold it.
    pub latched: bool,
}

impl TopicSpec {
    pub(super) fn new(
        topic: &str,
        message_type: &str,
        rate_hz: f64,
        kind: TopicKind,
        owner: &str,
    ) -> Self {
        TopicSpec {
            topic: topic.to_string(),
            message_type: message_type.to_string(),
            rate_hz,
            is_image: matches!(kind, TopicKind::Color | TopicKind::Depth),
            kind,
            owner: owner.to_string(),
            latched: kind == TopicKind::TfStatic,
        }
    }
}

/// What a topic is to the rig.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TopicKind {
    /// A camera's colour images.
    Color,
    /// An arm's joint states.
    Joints,
    /// A gripper's joint states.
    Gripper,
    /// An arm's or gripper's command topic.
    Command,
    /// A camera's registered depth.
    Depth,
    /// A camera's (or its depth image's) `sensor_msgs/msg/CameraInfo`.
    CameraInfo,
    /// `/tf`.
    Tf,
    /// `/tf_static` (latched).
    TfStatic,
    /// A further topic the rig lists or `record --topic` adds, recorded verbatim.
    Extra,
}

/// A further topic to record verbatim, whatever its type (`[[topic]]` in a rig file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExtraTopic {
    /// The ROS 2 topic, e.g. `/diagnostics`.
    pub name: String,
    /// Its full ROS 2 type, e.g. `diagnostic_msgs/msg/DiagnosticArray`.
    #[serde(rename = "type")]
    pub message_type: String,
    /// Its nominal rate (Hz), checked by the episode's verdict when given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_hz: Option<f64>,
    /// Transient-local: published once (a robot description, a map), kept in every episode.
    #[serde(default)]
    pub latched: bool,
}

/// `/tf` and `/tf_static` as tf2 publishes them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TfTopics {
    /// Record `/tf` (default true).
    #[serde(default = "yes")]
    pub dynamic: bool,
    /// Record `/tf_static`, latched (default true).
    #[serde(default = "yes", rename = "static")]
    pub static_: bool,
    /// The nominal rate of `/tf` (Hz), checked by the verdict when given (robot_state_publisher
    /// publishes at the joint states' rate, a driver at its own).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_hz: Option<f64>,
    /// The dynamic topic's name (default `/tf`; a namespaced robot's `/<ns>/tf`).
    #[serde(default = "tf_topic", skip_serializing_if = "is_tf_topic")]
    pub topic: String,
    /// The latched topic's name (default `/tf_static`).
    #[serde(
        default = "tf_static_topic",
        skip_serializing_if = "is_tf_static_topic"
    )]
    pub static_topic: String,
}

impl Default for TfTopics {
    /// Both `/tf` and `/tf_static`, no rate.
    fn default() -> Self {
        Self {
            dynamic: true,
            static_: true,
            rate_hz: None,
            topic: tf_topic(),
            static_topic: tf_static_topic(),
        }
    }
}

fn yes() -> bool {
    true
}

fn tf_topic() -> String {
    "/tf".into()
}

fn tf_static_topic() -> String {
    "/tf_static".into()
}

pub(super) fn is_tf_topic(t: &str) -> bool {
    t == "/tf"
}

pub(super) fn is_tf_static_topic(t: &str) -> bool {
    t == "/tf_static"
}

/// `tf2_msgs/msg/TFMessage`.
pub const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";
/// `sensor_msgs/msg/CameraInfo`.
pub const CAMERA_INFO: &str = "sensor_msgs/msg/CameraInfo";
pub(super) const JOINT_STATE: &str = "sensor_msgs/msg/JointState";
