//! Time series of one episode before alignment: the stamps a topic's messages carry, put in
//! stamp order within a small window (a second publisher, a driver whose stamps wobble), and
//! the joint positions (mapped by name) or command poses they hold.

use std::path::Path;

use scaledp_schema::kinematics::{rpy_from_rotation, unwrap_angles};
use scaledp_schema::rig::Arm;

use crate::decode;
use crate::error::{Error, Result};
use crate::kinematics::ArmKinematics;
use crate::options::ConvertOptions;
use crate::source::{RawMessage, Recording};
use scaledp_align::Stream;

/// The capture time of a message: its header stamp, or its log time with `--log-time` or when
/// the header holds none.
pub(crate) fn stamp_of(header_ns: u64, log_time_ns: u64, opts: &ConvertOptions) -> u64 {
    if opts.use_log_time || header_ns == 0 {
        log_time_ns
    } else {
        header_ns
    }
}

/// The messages of `topic` logged inside the options' window, in stored order.
pub(crate) fn messages_of<'r>(
    rec: &'r Recording,
    topic: &str,
    opts: &ConvertOptions,
) -> Vec<&'r RawMessage> {
    rec.messages
        .iter()
        .filter(|m| m.topic == topic && opts.in_window(m.log_time_ns))
        .collect()
}

/// Longest hole between consecutive stamps of a topic (1 h): one longer is a clock jump, not a
/// pause (a bag with pauses is split with `--split-gap`).
const MAX_HOLE_NS: u64 = 3_600_000_000_000;

/// Stamps in stored order put in stamp order: `order[k]` is the stored position of the k-th
/// stamp. A message may come after later-stamped ones by at most the reorder window; a stamp
/// further behind than that is a clock jump, and the episode is refused.
#[derive(Debug)]
pub(crate) struct Ordered {
    /// Stored positions, in stamp order.
    pub order: Vec<usize>,
    /// Messages stored after a later-stamped one (moved by the sort).
    pub reordered: usize,
}

impl Ordered {
    /// Orders `stamps` (of `topic` in `path`), or refuses a step back beyond `window_ns` or
    /// forward beyond [`MAX_HOLE_NS`].
    pub fn new(path: &Path, topic: &str, stamps: &[u64], window_ns: u64) -> Result<Self> {
        let mut latest = 0u64;
        let mut reordered = 0;
        for (i, &s) in stamps.iter().enumerate() {
            if s >= latest {
                if i > 0 && s - latest > MAX_HOLE_NS {
                    return Err(Error::Rejected {
                        path: path.into(),
                        reason: format!(
                            "time jumps forward on {topic}: message {i} is stamped {s} ns, \
                             {:.0} s after the one before: a clock jump",
                            (s - latest) as f64 * 1e-9
                        ),
                    });
                }
                latest = s;
                continue;
            }
            let behind = latest - s;
            if behind > window_ns {
                return Err(Error::Rejected {
                    path: path.into(),
                    reason: format!(
                        "time runs backwards on {topic}: message {i} is stamped {s} ns, {:.3} s \
                         before an earlier message ({latest} ns), beyond the {:.3} s reorder \
                         window: a clock jump",
                        behind as f64 * 1e-9,
                        window_ns as f64 * 1e-9
                    ),
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
}

/// A JointState topic as stamps plus positions of the wanted joints (mapped by name, never by
/// index), in stamp order.
pub(crate) struct JointSeries {
    /// The stamps, nominal period and topic.
    pub stream: Stream,
    /// Positions per stamp, in the order of the names asked for.
    pub positions: Vec<Vec<f64>>,
    /// Messages put back in stamp order.
    pub reordered: usize,
}

impl JointSeries {
    /// Reads `names` from the JointState messages `msgs` of `topic` (nominal rate `rate`).
    pub fn read(
        path: &Path,
        msgs: &[&RawMessage],
        topic: &str,
        names: &[String],
        rate: f64,
        opts: &ConvertOptions,
    ) -> Result<Self> {
        let mut stamps = Vec::with_capacity(msgs.len());
        let mut positions = Vec::with_capacity(msgs.len());
        // Where each wanted joint sits in the message; re-mapped whenever the name list changes.
        let mut seen_names: Vec<String> = Vec::new();
        let mut index: Vec<Option<usize>> = Vec::new();
        for m in msgs {
            let js = decode::joint_state(path, m)?;
            if js.name.len() != js.position.len() {
                return Err(Error::Message {
                    path: path.into(),
                    topic: topic.into(),
                    log_time_ns: m.log_time_ns,
                    reason: format!(
                        "{} names but {} positions",
                        js.name.len(),
                        js.position.len()
                    ),
                });
            }
            if js.name != seen_names {
                index = names
                    .iter()
                    .map(|n| js.name.iter().position(|x| x == n))
                    .collect();
                seen_names = js.name.clone();
            }
            let mut q = Vec::with_capacity(names.len());
            for (n, i) in names.iter().zip(&index) {
                let i = i.ok_or_else(|| Error::Rejected {
                    path: path.into(),
                    reason: format!("joint '{n}' is missing from {topic} (it has {:?})", js.name),
                })?;
                let v = js.position[i];
                if !v.is_finite() {
                    return Err(Error::Rejected {
                        path: path.into(),
                        reason: format!("joint '{n}' on {topic} is {v} at {} ns", m.log_time_ns),
                    });
                }
                q.push(v);
            }
            stamps.push(stamp_of(js.header.stamp.as_ns(), m.log_time_ns, opts));
            positions.push(q);
        }
        let ordered = Ordered::new(path, topic, &stamps, opts.reorder_window_ns())?;
        let (stamps, positions) = if ordered.reordered > 0 {
            let s = ordered.order.iter().map(|&i| stamps[i]).collect();
            let p = ordered
                .order
                .iter()
                .map(|&i| positions[i].clone())
                .collect();
            (s, p)
        } else {
            (stamps, positions)
        };
        Ok(Self {
            stream: Stream::new(topic, stamps, Some(rate)),
            positions,
            reordered: ordered.reordered,
        })
    }

    /// Positions interpolated with a bracket from [`Stream::bracket`].
    pub fn interpolate(&self, (i, j, w): (usize, usize, f64)) -> Vec<f64> {
        crate::kinematics::lerp(&self.positions[i], &self.positions[j], w)
    }
}

/// Stamps (in order), unwrapped TCP poses and reordered count of a command topic: `PoseStamped`
/// targets as they are, a leader arm's `JointState` through this arm's kinematics.
pub(crate) struct CommandPoses {
    pub stamps_ns: Vec<u64>,
    pub poses: Vec<[f64; 6]>,
    pub reordered: usize,
}

impl CommandPoses {
    /// Reads the command messages `msgs` of `arm`.
    pub fn read(
        path: &Path,
        msgs: &[&RawMessage],
        arm: &Arm,
        kin: &ArmKinematics,
        opts: &ConvertOptions,
    ) -> Result<Self> {
        let topic = msgs.first().map(|m| m.topic.clone()).unwrap_or_default();
        let (stamps, mut poses, reordered) = if msgs
            .first()
            .is_some_and(|m| m.message_type.ends_with("/PoseStamped"))
        {
            let mut stamps = Vec::with_capacity(msgs.len());
            let mut poses = Vec::with_capacity(msgs.len());
            for m in msgs {
                let p = decode::pose_stamped(path, m)?;
                let o = p.pose.orientation;
                let q = glam::DQuat::from_xyzw(o.x, o.y, o.z, o.w).normalize();
                let [roll, pitch, yaw] = rpy_from_rotation(glam::DMat3::from_quat(q));
                let at = p.pose.position;
                stamps.push(stamp_of(p.header.stamp.as_ns(), m.log_time_ns, opts));
                poses.push([at.x, at.y, at.z, roll, pitch, yaw]);
            }
            let ordered = Ordered::new(path, &topic, &stamps, opts.reorder_window_ns())?;
            let s = ordered.order.iter().map(|&i| stamps[i]).collect();
            let p = ordered.order.iter().map(|&i| poses[i]).collect();
            (s, p, ordered.reordered)
        } else {
            let series =
                JointSeries::read(path, msgs, &topic, &arm.joint_names, arm.rate_hz, opts)?;
            let mut poses = Vec::with_capacity(series.positions.len());
            for q in &series.positions {
                poses.push(kin.tcp_pose(q).map_err(|e| Error::Rejected {
                    path: path.into(),
                    reason: format!("{topic}: {e}"),
                })?);
            }
            (series.stream.stamps_ns, poses, series.reordered)
        };
        unwrap_pose_angles(&mut poses);
        Ok(Self {
            stamps_ns: stamps,
            poses,
            reordered,
        })
    }
}

/// Unwraps roll, pitch and yaw of consecutive poses (no jump of more than π between two).
pub(crate) fn unwrap_pose_angles(poses: &mut [[f64; 6]]) {
    for axis in 3..6 {
        let mut col: Vec<f64> = poses.iter().map(|p| p[axis]).collect();
        unwrap_angles(&mut col);
        for (p, v) in poses.iter_mut().zip(col) {
            p[axis] = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn order(stamps: &[u64], window: u64) -> Result<Ordered> {
        Ordered::new(Path::new("x.mcap"), "/t", stamps, window)
    }

    #[test]
    fn stamps_a_little_out_of_order_are_sorted_and_counted() {
        let o = order(&[10, 20, 15, 30, 29, 28, 40], 10).unwrap();
        assert_eq!(o.order, vec![0, 2, 1, 5, 4, 3, 6]);
        assert_eq!(o.reordered, 3);
        let o = order(&[1, 2, 2, 3], 0).unwrap();
        assert_eq!((o.order, o.reordered), (vec![0, 1, 2, 3], 0));
    }

    #[test]
    fn a_hole_of_more_than_an_hour_is_a_clock_jump() {
        let hour = 3_600_000_000_000;
        assert!(order(&[0, hour], 0).is_ok());
        let e = order(&[0, 1, hour + 2], 0).unwrap_err().to_string();
        assert!(e.contains("time jumps forward on /t: message 2"), "{e}");
    }

    #[test]
    fn a_step_back_beyond_the_window_is_a_clock_jump() {
        let e = order(&[1_000_000_000, 2_000_000_000, 1_500_000_000], 100_000_000)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("time runs backwards on /t")
                && e.contains("0.500 s")
                && e.contains("clock jump"),
            "{e}"
        );
    }
}
