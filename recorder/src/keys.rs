//! How ROS 2 topics appear as Zenoh key expressions, and what rmw_zenoh attaches to samples.

use zenoh::bytes::ZBytes;

/// The key zenoh-bridge-ros2dds uses for a topic: the name without its leading `/`, behind the
/// bridge's namespace (if any, also without slashes at either end).
pub fn bridge_key(namespace: &str, topic: &str) -> String {
    let topic = topic.trim_matches('/');
    let ns = namespace.trim_matches('/');
    if ns.is_empty() {
        topic.to_string()
    } else {
        format!("{ns}/{topic}")
    }
}

/// The DDS-style type name rmw_zenoh puts in keys: `sensor_msgs/msg/Image` →
/// `sensor_msgs::msg::dds_::Image_`.
pub fn rmw_type_name(message_type: &str) -> String {
    let mut parts: Vec<&str> = message_type.split('/').collect();
    let name = parts.pop().unwrap_or_default();
    parts.push("dds_");
    format!("{}::{name}_", parts.join("::"))
}

/// A key expression matching an rmw_zenoh data key for `topic` on any domain with any type hash:
/// `*/<topic>/<pkg::msg::dds_::Type_>/*`.
pub fn rmw_key_expr(topic: &str, message_type: &str) -> String {
    format!(
        "*/{}/{}/*",
        topic.trim_matches('/'),
        rmw_type_name(message_type)
    )
}

/// The rmw_zenoh key a publisher in `domain` uses, with the hash given (tests and the simulator).
pub fn rmw_key(domain: u32, topic: &str, message_type: &str, type_hash: &str) -> String {
    format!(
        "{domain}/{}/{}/{type_hash}",
        topic.trim_matches('/'),
        rmw_type_name(message_type)
    )
}

/// What rmw_zenoh attaches to each sample (zenoh-ext serialization, keys as strings).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RmwAttachment {
    /// Per-publisher sequence number, starting at 1.
    pub sequence_number: i64,
    /// Publisher's clock when the sample was sent (ns).
    pub source_timestamp_ns: i64,
    /// Publisher's global id (16 bytes on Iron and later, 24 on Humble).
    pub source_gid: Vec<u8>,
}

impl RmwAttachment {
    /// Parses an attachment; `None` when it is not rmw_zenoh's layout.
    pub fn parse(bytes: &ZBytes) -> Option<Self> {
        fn key(d: &mut zenoh_ext::ZDeserializer<'_>, name: &str) -> Option<()> {
            d.deserialize::<String>()
                .ok()
                .filter(|k| k == name)
                .map(drop)
        }
        let mut d = zenoh_ext::ZDeserializer::new(bytes);
        key(&mut d, "sequence_number")?;
        let sequence_number = d.deserialize::<i64>().ok()?;
        key(&mut d, "source_timestamp")?;
        let source_timestamp_ns = d.deserialize::<i64>().ok()?;
        key(&mut d, "source_gid")?;
        let source_gid = d.deserialize::<Vec<u8>>().unwrap_or_default();
        Some(Self {
            sequence_number,
            source_timestamp_ns,
            source_gid,
        })
    }

    /// Serializes in rmw_zenoh's layout (used by the simulator's rmw mode and by tests).
    pub fn to_zbytes(&self) -> ZBytes {
        let mut s = zenoh_ext::ZSerializer::new();
        s.serialize("sequence_number");
        s.serialize(self.sequence_number);
        s.serialize("source_timestamp");
        s.serialize(self.source_timestamp_ns);
        s.serialize("source_gid");
        s.serialize(&self.source_gid);
        s.finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_follow_the_bridge_and_rmw_zenoh() {
        assert_eq!(
            bridge_key("", "/zed/zed_node/rgb/color/rect/image"),
            "zed/zed_node/rgb/color/rect/image"
        );
        assert_eq!(
            bridge_key("/robot1/", "/joint_states"),
            "robot1/joint_states"
        );
        assert_eq!(
            rmw_type_name("sensor_msgs/msg/Image"),
            "sensor_msgs::msg::dds_::Image_"
        );
        assert_eq!(
            rmw_key_expr("/franka/joint_states", "sensor_msgs/msg/JointState"),
            "*/franka/joint_states/sensor_msgs::msg::dds_::JointState_/*"
        );
    }

    #[test]
    fn attachment_round_trips() {
        let a = RmwAttachment {
            sequence_number: 42,
            source_timestamp_ns: 1_700_000_000_123,
            source_gid: vec![7; 16],
        };
        assert_eq!(RmwAttachment::parse(&a.to_zbytes()), Some(a));
        assert_eq!(RmwAttachment::parse(&ZBytes::from(vec![1u8, 2, 3])), None);
    }
}
