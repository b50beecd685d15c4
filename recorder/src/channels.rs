//! Each recorded topic as the writer sees it: its rig description, the channel written for it
//! (with the `ros2msg` schema found for its type) and where its capture stamp is.

use scaledp_schema::msg::{MsgSearch, StampField};
use scaledp_schema::rig::{TopicKind, TopicSpec};

use crate::episode::ChannelSpec;

/// One topic of a session.
#[derive(Debug, Clone)]
pub(crate) struct Channel {
    /// As the rig (or a `--topic` pattern) describes it.
    pub spec: TopicSpec,
    /// What an episode file declares for it.
    pub channel: ChannelSpec,
    /// Where `publish_time` comes from.
    pub stamp: StampField,
}

impl Channel {
    /// `spec` with the definition of its type from `search` (scaledp's own, else `.msg` files);
    /// a type found nowhere gets an empty schema and one warning naming the topic, and an
    /// unknown type (`spec.message_type` empty) no schema at all.
    pub fn resolve(spec: TopicSpec, search: &mut MsgSearch) -> Self {
        let message_type = (!spec.message_type.is_empty()).then(|| spec.message_type.clone());
        let definition = match &message_type {
            Some(t) => search.definition(t).unwrap_or_else(|| {
                tracing::warn!(
                    "{}: no ros2msg definition for {t} in scaledp or in {} searched directories \
                     (AMENT_PREFIX_PATH, --msg-path): recorded with an empty schema",
                    spec.topic,
                    search.dirs().len()
                );
                String::new()
            }),
            None => {
                tracing::warn!(
                    "{}: its type is not known (a bridge key carries none; give it as \
                     --topic NAME:TYPE): recorded without a schema",
                    spec.topic
                );
                String::new()
            }
        };
        Self {
            stamp: StampField::of_definition(&definition),
            channel: ChannelSpec {
                topic: spec.topic.clone(),
                message_type,
                definition,
                latched: spec.latched,
            },
            spec,
        }
    }
}

/// A further topic found by a `--topic` pattern.
pub(crate) fn discovered(topic: &str, message_type: Option<&str>) -> TopicSpec {
    TopicSpec {
        topic: topic.to_string(),
        message_type: message_type.unwrap_or_default().to_string(),
        rate_hz: 0.0,
        is_image: message_type.is_some_and(|t| t.ends_with("/Image")),
        kind: TopicKind::Extra,
        owner: String::new(),
        latched: false,
    }
}
