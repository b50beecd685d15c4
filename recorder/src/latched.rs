//! The latest message of every transient-local ("latched") publisher, kept across episodes so
//! each episode starts with them (tf2's `/tf_static` is published once, at startup).
//!
//! A publisher is known by its rmw_zenoh gid. zenoh-bridge-ros2dds gives none (it serves every
//! DDS writer of a topic through one route and one cache), so without a gid each distinct
//! message counts as its own publisher: two `static_transform_publisher`s behind a bridge are
//! both kept, and a message seen twice (live and from a cache) is kept once.

use std::collections::VecDeque;

/// At most this many publishers per topic are remembered (the oldest is forgotten first).
const MAX_PER_TOPIC: usize = 64;

/// A latched message as first received.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Latched {
    /// Who published it: the gid, or for a publisher without one, the message itself.
    publisher: Vec<u8>,
    /// The CDR payload.
    pub payload: Vec<u8>,
    /// When it was published (ns): its stamp, the sender's clock, or when it arrived.
    pub publish_ns: u64,
}

/// Per topic number, the latest message of each publisher, oldest first.
#[derive(Debug, Default)]
pub(crate) struct LatchedStore {
    topics: Vec<VecDeque<Latched>>,
}

impl LatchedStore {
    /// Keeps `payload` as the latest of its publisher on `topic`; true when it is new (not the
    /// very message already kept).
    pub fn update(
        &mut self,
        topic: usize,
        gid: Option<&[u8]>,
        payload: &[u8],
        publish_ns: u64,
    ) -> bool {
        if self.topics.len() <= topic {
            self.topics.resize_with(topic + 1, VecDeque::new);
        }
        let kept = &mut self.topics[topic];
        let publisher = gid.unwrap_or(payload);
        if let Some(i) = kept.iter().position(|l| l.publisher == publisher) {
            if kept[i].payload == payload {
                return false;
            }
            kept.remove(i);
        }
        if kept.len() >= MAX_PER_TOPIC {
            kept.pop_front();
        }
        kept.push_back(Latched {
            publisher: publisher.to_vec(),
            payload: payload.to_vec(),
            publish_ns,
        });
        true
    }

    /// What is kept for `topic`, in the order it arrived.
    pub fn of(&self, topic: usize) -> impl Iterator<Item = &Latched> {
        self.topics.get(topic).into_iter().flatten()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_latest_per_publisher_is_kept_once() {
        let mut s = LatchedStore::default();
        assert!(s.update(2, Some(b"gid-a"), b"one", 1));
        assert!(
            !s.update(2, Some(b"gid-a"), b"one", 1),
            "seen again: not new"
        );
        assert!(s.update(2, Some(b"gid-b"), b"other", 2));
        assert!(
            s.update(2, Some(b"gid-a"), b"two", 3),
            "a's newer message replaces its first"
        );
        let kept: Vec<&[u8]> = s.of(2).map(|l| l.payload.as_slice()).collect();
        assert_eq!(kept, [b"other".as_slice(), b"two"]);
        // Without a gid (a bridge), every distinct message is kept, each once.
        assert!(s.update(0, None, b"x", 1) && s.update(0, None, b"y", 2));
        assert!(!s.update(0, None, b"x", 5));
        assert_eq!(s.of(0).count(), 2);
        assert_eq!(s.of(7).count(), 0);
        for k in 0..(MAX_PER_TOPIC as u64 + 5) {
            s.update(1, None, &k.to_le_bytes(), k);
        }
        assert_eq!(s.of(1).count(), MAX_PER_TOPIC);
        assert_eq!(
            s.of(1).next().unwrap().publish_ns,
            5,
            "the oldest went first"
        );
    }
}
