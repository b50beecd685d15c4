//! Further topics asked for by name (`record --topic NAME[:TYPE]`): a ROS 2 topic, or a glob of
//! them with Zenoh's wildcards (`*` one name level, `**` any number), and an optional type.

use std::fmt;
use std::str::FromStr;

use crate::keys::{bridge_key, rmw_type_name};

/// `NAME[:TYPE]` as `record --topic` takes it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicPattern {
    name: String,
    message_type: Option<String>,
}

impl TopicPattern {
    /// The topic or glob, with its leading `/`.
    pub fn name(&self) -> &str {
        &self.name
    }
    /// The type given, as `pkg/msg/Name`.
    pub fn message_type(&self) -> Option<&str> {
        self.message_type.as_deref()
    }
    /// True when the name holds `*` or `**`.
    pub fn is_glob(&self) -> bool {
        self.name.split('/').any(|s| s == "*" || s == "**")
    }
    /// The key expression zenoh-bridge-ros2dds publishes matching topics under.
    pub fn bridge_key_expr(&self, namespace: &str) -> String {
        bridge_key(namespace, &self.name)
    }
    /// The key expression of matching rmw_zenoh data keys (any domain, type as given or any,
    /// any type hash).
    pub fn rmw_key_expr(&self) -> String {
        let topic = self.name.trim_matches('/');
        match (&self.message_type, topic.ends_with("**")) {
            (Some(t), _) => format!("*/{topic}/{}/*", rmw_type_name(t)),
            // `**` already spans the type and hash segments.
            (None, true) => format!("*/{topic}"),
            (None, false) => format!("*/{topic}/*/*"),
        }
    }
    /// Whether `topic` (a concrete name) is one this pattern asks for.
    pub fn matches(&self, topic: &str) -> bool {
        fn go(p: &[&str], t: &[&str]) -> bool {
            match (p.first(), t.first()) {
                (None, None) => true,
                (Some(&"**"), _) => go(&p[1..], t) || (!t.is_empty() && go(p, &t[1..])),
                (Some(&"*"), Some(_)) => go(&p[1..], &t[1..]),
                (Some(a), Some(b)) => a == b && go(&p[1..], &t[1..]),
                _ => false,
            }
        }
        let p: Vec<&str> = self.name.trim_matches('/').split('/').collect();
        let t: Vec<&str> = topic.trim_matches('/').split('/').collect();
        go(&p, &t)
    }
}

fn valid_word(w: &str) -> bool {
    !w.is_empty() && w.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// A full ROS 2 message type (`pkg/msg/Name`, also `pkg/Name`), as `pkg/msg/Name`.
pub fn parse_message_type(text: &str) -> Result<String, String> {
    let parts: Vec<&str> = text.split('/').collect();
    let (pkg, name) = match parts.as_slice() {
        [pkg, "msg", name] | [pkg, name] => (*pkg, *name),
        _ => {
            return Err(format!(
                "type '{text}' is not a ROS 2 message type like sensor_msgs/msg/Image"
            ))
        }
    };
    if !valid_word(pkg) || !valid_word(name) {
        return Err(format!(
            "type '{text}' is not a ROS 2 message type like sensor_msgs/msg/Image"
        ));
    }
    Ok(format!("{pkg}/msg/{name}"))
}

impl FromStr for TopicPattern {
    type Err = String;

    /// `NAME[:TYPE]`: NAME absolute (`/ns/topic`), its levels letters, digits and `_`, or a
    /// whole level `*` / `**`; TYPE `pkg/msg/Name`.
    fn from_str(s: &str) -> Result<Self, String> {
        let (name, ty) = match s.split_once(':') {
            Some((n, t)) => (n, Some(t)),
            None => (s, None),
        };
        if !name.starts_with('/') || name.len() < 2 || name.ends_with('/') {
            return Err(format!(
                "topic '{name}' must be absolute, like /ns/name (or a glob like /ns/**)"
            ));
        }
        for level in name[1..].split('/') {
            if level == "*" || level == "**" {
                continue;
            }
            if level.contains('*') {
                return Err(format!(
                    "topic '{name}': '*' stands for a whole level ('/ns/*', '/ns/**'), as Zenoh matches keys"
                ));
            }
            if !valid_word(level) {
                return Err(format!(
                    "topic '{name}': '{level}' is not a ROS 2 name (letters, digits, '_')"
                ));
            }
        }
        let message_type = ty.map(parse_message_type).transpose()?;
        Ok(Self {
            name: name.to_string(),
            message_type,
        })
    }
}

impl fmt::Display for TopicPattern {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.message_type {
            Some(t) => write!(f, "{}:{t}", self.name),
            None => f.write_str(&self.name),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_types_parse_or_say_what_is_wrong() {
        let p: TopicPattern = "/diagnostics:diagnostic_msgs/DiagnosticArray"
            .parse()
            .unwrap();
        assert_eq!(p.name(), "/diagnostics");
        assert_eq!(
            p.message_type(),
            Some("diagnostic_msgs/msg/DiagnosticArray")
        );
        assert!(!p.is_glob());
        assert_eq!(
            p.rmw_key_expr(),
            "*/diagnostics/diagnostic_msgs::msg::dds_::DiagnosticArray_/*"
        );
        let g: TopicPattern = "/robot/**".parse().unwrap();
        assert!(g.is_glob());
        assert_eq!(g.bridge_key_expr("ns"), "ns/robot/**");
        assert_eq!(g.rmw_key_expr(), "*/robot/**");
        assert!(g.matches("/robot/a/b") && !g.matches("/other/a"));
        let one: TopicPattern = "/cam/*/info".parse().unwrap();
        assert_eq!(one.rmw_key_expr(), "*/cam/*/info/*/*");
        assert!(one.matches("/cam/x/info") && !one.matches("/cam/x/y/info"));
        assert_eq!(one.to_string(), "/cam/*/info");
        for (bad, want) in [
            ("diagnostics", "must be absolute"),
            ("/a//b", "is not a ROS 2 name"),
            ("/cam*", "whole level"),
            ("/a:DiagnosticArray", "not a ROS 2 message type"),
            ("/a:pkg/srv/X", "not a ROS 2 message type"),
            ("/a/", "must be absolute"),
        ] {
            let e = bad.parse::<TopicPattern>().unwrap_err();
            assert!(e.contains(want), "{bad}: {e}");
            assert!(!e.contains('\n'), "one line: {e}");
        }
    }
}
