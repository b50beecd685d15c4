//! Stamps put in stamp order, as the converter and the recorder's verdict both take them: a
//! message may come after later-stamped ones by at most a reorder window (a second publisher, a
//! driver whose stamps wobble); a stamp further behind, or a hole of more than an hour, is a
//! clock jump and the episode is refused.

/// The reorder window `scaledp convert` uses unless told otherwise (`--reorder-window`).
pub const DEFAULT_REORDER_WINDOW_S: f64 = 0.1;

/// Longest hole between consecutive stamps of a topic (1 h): one longer is a clock jump, not a
/// pause (a bag with pauses is split with `convert --split-gap`).
pub const MAX_HOLE_NS: u64 = 3_600_000_000_000;

/// Why a topic's stamps cannot be put in order.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ClockJump {
    /// A hole longer than [`MAX_HOLE_NS`].
    #[error(
        "time jumps forward on {topic}: message {index} is stamped {stamp_ns} ns, {:.0} s after \
         the one before: a clock jump",
        *.hole_ns as f64 * 1e-9
    )]
    Forward {
        /// The topic.
        topic: String,
        /// The message's stored position.
        index: usize,
        /// Its stamp.
        stamp_ns: u64,
        /// The hole before it.
        hole_ns: u64,
    },
    /// A stamp further behind an earlier one than the reorder window.
    #[error(
        "time runs backwards on {topic}: message {index} is stamped {stamp_ns} ns, {:.3} s before \
         an earlier message ({latest_ns} ns), beyond the {:.3} s reorder window: a clock jump",
        (*.latest_ns - *.stamp_ns) as f64 * 1e-9,
        *.window_ns as f64 * 1e-9
    )]
    Backward {
        /// The topic.
        topic: String,
        /// The message's stored position.
        index: usize,
        /// Its stamp.
        stamp_ns: u64,
        /// The latest stamp before it.
        latest_ns: u64,
        /// The reorder window.
        window_ns: u64,
    },
}

/// Stamps in stored order put in stamp order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StampOrder {
    /// Stored positions, in stamp order: `order[k]` is the stored position of the k-th stamp.
    pub order: Vec<usize>,
    /// Messages stored after a later-stamped one (moved by the sort).
    pub reordered: usize,
}

impl StampOrder {
    /// Orders the stamps of `topic` (stored order), or names the clock jump: a step back beyond
    /// `window_ns` or forward beyond [`MAX_HOLE_NS`].
    pub fn new(topic: &str, stamps: &[u64], window_ns: u64) -> Result<Self, ClockJump> {
        let mut latest = 0u64;
        let mut reordered = 0;
        for (index, &s) in stamps.iter().enumerate() {
            if s >= latest {
                if index > 0 && s - latest > MAX_HOLE_NS {
                    return Err(ClockJump::Forward {
                        topic: topic.into(),
                        index,
                        stamp_ns: s,
                        hole_ns: s - latest,
                    });
                }
                latest = s;
                continue;
            }
            if latest - s > window_ns {
                return Err(ClockJump::Backward {
                    topic: topic.into(),
                    index,
                    stamp_ns: s,
                    latest_ns: latest,
                    window_ns,
                });
            }
            reordered += 1;
        }
        let mut order: Vec<usize> = (0..stamps.len()).collect();
        if reordered > 0 {
            order.sort_by_key(|&i| stamps[i]);
        }
        Ok(Self { order, reordered })
    }

    /// The stamps themselves in stamp order.
    pub fn sorted(&self, stamps: &[u64]) -> Vec<u64> {
        self.order.iter().map(|&i| stamps[i]).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamps_a_little_out_of_order_are_sorted_and_counted() {
        let o = StampOrder::new("/t", &[10, 20, 15, 30, 29, 28, 40], 10).unwrap();
        assert_eq!(o.order, vec![0, 2, 1, 5, 4, 3, 6]);
        assert_eq!(o.reordered, 3);
        assert_eq!(
            o.sorted(&[10, 20, 15, 30, 29, 28, 40]),
            vec![10, 15, 20, 28, 29, 30, 40]
        );
        let o = StampOrder::new("/t", &[1, 2, 2, 3], 0).unwrap();
        assert_eq!((o.order, o.reordered), (vec![0, 1, 2, 3], 0));
    }

    #[test]
    fn a_hole_of_more_than_an_hour_is_a_clock_jump() {
        assert!(StampOrder::new("/t", &[0, MAX_HOLE_NS], 0).is_ok());
        let e = StampOrder::new("/t", &[0, 1, MAX_HOLE_NS + 2], 0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("time jumps forward on /t: message 2"), "{e}");
    }

    #[test]
    fn a_step_back_beyond_the_window_is_a_clock_jump() {
        let e = StampOrder::new(
            "/t",
            &[1_000_000_000, 2_000_000_000, 1_500_000_000],
            100_000_000,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("time runs backwards on /t")
                && e.contains("0.500 s")
                && e.contains("beyond the 0.100 s reorder window: a clock jump"),
            "{e}"
        );
    }
}
