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

/// The ROS 2 type of an rmw_zenoh key's type segment: `sensor_msgs::msg::dds_::Image_` →
/// `sensor_msgs/msg/Image`; `None` for anything else.
pub fn type_from_rmw(segment: &str) -> Option<String> {
    let (head, name) = segment.rsplit_once("::dds_::")?;
    let name = name.strip_suffix('_')?;
    let mut parts: Vec<&str> = head.split("::").collect();
    parts.push(name);
    (parts.len() == 3 && parts.iter().all(|p| !p.is_empty())).then(|| parts.join("/"))
}

/// Topic and type of an rmw_zenoh data key (`<domain>/<topic>/<type>/<hash>`); `None` when the
/// key is not one.
pub fn parse_rmw_key(key: &str) -> Option<(String, String)> {
    let segments: Vec<&str> = key.split('/').collect();
    let [domain, topic @ .., ty, _hash] = segments.as_slice() else {
        return None;
    };
    if topic.is_empty() || domain.is_empty() || !domain.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some((format!("/{}", topic.join("/")), type_from_rmw(ty)?))
}

/// The topic a zenoh-bridge-ros2dds key stands for (the bridge's namespace removed); `None`
/// for keys outside the namespace and for rmw_zenoh keys.
pub fn topic_from_bridge_key(namespace: &str, key: &str) -> Option<String> {
    if parse_rmw_key(key).is_some() {
        return None;
    }
    let ns = namespace.trim_matches('/');
    let rest = if ns.is_empty() {
        key
    } else {
        key.strip_prefix(ns)?.strip_prefix('/')?
    };
    (!rest.is_empty() && !rest.starts_with('@')).then(|| format!("/{rest}"))
}

/// Where zenoh-bridge-ros2dds up to 1.5.0 serves the transient-local publications of `key`
/// from its cache (a `PublicationCache` queryable per bridge: `<key>/@ros2_pub_cache/<zid>`),
/// with `*` for the bridge's id: a query here reaches every bridge's cache. Replies carry the
/// publications' own key, so the query must accept any key.
pub fn bridge_cache_selector(key: &str) -> String {
    format!("{key}/@ros2_pub_cache/*")
}

/// The queryable a bridge with id `zid` declares for `key`'s cache (the simulator's).
pub fn bridge_cache_queryable(key: &str, zid: &str) -> String {
    format!("{key}/@ros2_pub_cache/{zid}")
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
    fn keys_name_their_topic_and_type() {
        assert_eq!(
            parse_rmw_key(
                "0/zed/zed_node/depth/depth_registered/sensor_msgs::msg::dds_::Image_/RIHS01_ab"
            ),
            Some((
                "/zed/zed_node/depth/depth_registered".to_string(),
                "sensor_msgs/msg/Image".to_string()
            ))
        );
        assert_eq!(
            parse_rmw_key(&rmw_key(
                7,
                "/tf_static",
                "tf2_msgs/msg/TFMessage",
                "TypeHashNotSupported"
            )),
            Some((
                "/tf_static".to_string(),
                "tf2_msgs/msg/TFMessage".to_string()
            ))
        );
        for not_rmw in [
            "tf_static",
            "x/tf/tf2_msgs::msg::dds_::TFMessage_/h",
            "0/a/b/c",
            "0/T_/h",
        ] {
            assert_eq!(parse_rmw_key(not_rmw), None, "{not_rmw}");
        }
        assert_eq!(
            type_from_rmw("sensor_msgs::msg::dds_::CameraInfo_").as_deref(),
            Some("sensor_msgs/msg/CameraInfo")
        );
        assert_eq!(
            topic_from_bridge_key("", "tf_static").as_deref(),
            Some("/tf_static")
        );
        assert_eq!(
            topic_from_bridge_key("/robot1", "robot1/tf").as_deref(),
            Some("/tf")
        );
        assert_eq!(topic_from_bridge_key("robot1", "robot2/tf"), None);
        assert_eq!(
            topic_from_bridge_key("", "0/tf/tf2_msgs::msg::dds_::TFMessage_/h"),
            None
        );
        assert_eq!(
            bridge_cache_selector("tf_static"),
            "tf_static/@ros2_pub_cache/*"
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
