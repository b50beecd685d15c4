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
use scaledp_align::{StampOrder as Ordered, Stream};

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

/// The stamps of `topic` in `path` put in stamp order ([`scaledp_align::StampOrder`]), or the
/// episode refused for a clock jump.
pub(crate) fn ordered(path: &Path, topic: &str, stamps: &[u64], window_ns: u64) -> Result<Ordered> {
    Ordered::new(topic, stamps, window_ns).map_err(|e| Error::Rejected {
        path: path.into(),
        reason: e.to_string(),
    })
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
        let ordered = ordered(path, topic, &stamps, opts.reorder_window_ns())?;
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
            let ordered = ordered(path, &topic, &stamps, opts.reorder_window_ns())?;
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

    #[test]
    fn a_clock_jump_rejects_the_episode_by_name() {
        let e = ordered(Path::new("x.mcap"), "/t", &[0, 1, 3_600_000_000_002], 0)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("x.mcap") && e.contains("time jumps forward on /t"),
            "{e}"
        );
    }
}
