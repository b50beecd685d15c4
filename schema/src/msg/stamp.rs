//! Where a message's capture stamp is, read from its `ros2msg` definition: what a recorder
//! takes as `publish_time` for any type, known or looked up.

use super::base::{header_stamp, RosMessage, Time};
use super::texts::short_name;
use crate::cdr::CdrReader;

/// Where a message's capture stamp is, as its definition says: what a recorder takes as a
/// message's `publish_time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StampField {
    /// The first field is a `std_msgs/Header` (or a `builtin_interfaces/Time`): its stamp.
    Leading,
    /// The first field is a sequence of messages that start with a header (`tf2_msgs/TFMessage`,
    /// `visualization_msgs/MarkerArray`): the first element's stamp, none when it is empty.
    FirstElement,
    /// No stamp to read.
    None,
}

/// The type of the first field of a `.msg` text (constants, comments and blank lines skipped).
fn first_field_type(text: &str) -> Option<&str> {
    text.lines()
        .map(|l| l.split('#').next().unwrap_or_default().trim())
        .filter(|l| !l.is_empty())
        .find(|l| {
            // A constant: `TYPE NAME=VALUE`.
            let mut words = l.split_whitespace();
            let _ = words.next();
            !words.next().is_some_and(|name| name.contains('='))
        })
        .and_then(|l| l.split_whitespace().next())
}

fn is_stamp_type(t: &str) -> bool {
    matches!(
        short_name(t).as_str(),
        "std_msgs/Header" | "Header" | "builtin_interfaces/Time"
    )
}

impl StampField {
    /// Reads it from a `ros2msg` definition (the root text, and for a sequence its element's
    /// `MSG:` section).
    pub fn of_definition(definition: &str) -> Self {
        let line = "=".repeat(80);
        let mut sections = definition.split(line.as_str());
        let root = sections.next().unwrap_or_default();
        let Some(first) = first_field_type(root) else {
            return Self::None;
        };
        if is_stamp_type(first) {
            return Self::Leading;
        }
        let Some(element) = first.strip_suffix("[]") else {
            return Self::None;
        };
        let element = short_name(element);
        for s in sections {
            let s = s.trim_start_matches('\n');
            let Some((head, body)) = s.split_once('\n') else {
                continue;
            };
            let name = head.trim().strip_prefix("MSG:").unwrap_or_default().trim();
            if short_name(name) == element {
                return match first_field_type(body) {
                    Some(t) if is_stamp_type(t) => Self::FirstElement,
                    _ => Self::None,
                };
            }
        }
        Self::None
    }

    /// The stamp in `payload`, when there is one to read.
    pub fn read(self, payload: &[u8]) -> Option<Time> {
        match self {
            Self::Leading => header_stamp(payload).ok(),
            Self::FirstElement => {
                let mut r = CdrReader::new(payload).ok()?;
                // Each element holds at least a header's 8-byte stamp.
                if r.sequence_len(8).ok()? == 0 {
                    return None;
                }
                Time::read(&mut r).ok()
            }
            Self::None => None,
        }
    }
}
