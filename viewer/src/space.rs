//! How a rig's state and action vectors split into arms in either action space: each arm's
//! values, what each one is called in the plots, and where a row puts the arm's TCP in 3-D
//! (its x, y, z in TCP space; forward kinematics of its joints in joint space).

use std::ops::Range;

use scaledp_converter::live::ArmKinematics;
use scaledp_schema::{ActionSpace, Rig};

use crate::layout;

/// One arm's part of a state or action vector.
pub(crate) struct ArmDims {
    /// Where its values sit.
    pub range: Range<usize>,
    /// What each value is called (`x` … `gripper`, or its joints' names and `gripper`).
    pub labels: Vec<String>,
    /// Forward kinematics, for joint-space rows (None in TCP space, or without a model).
    kin: Option<ArmKinematics>,
}

/// The arms of a rig's vectors in one action space.
pub(crate) struct Dims {
    pub space: ActionSpace,
    pub arms: Vec<ArmDims>,
    dim: usize,
}

/// An arm's labels in `space`.
pub(crate) fn labels(arm: &scaledp_schema::rig::Arm, space: ActionSpace) -> Vec<String> {
    match space {
        ActionSpace::Tcp => layout::POSE_DIMS.iter().map(|d| d.to_string()).collect(),
        ActionSpace::Joints => arm
            .joint_names
            .iter()
            .map(|j| j.rsplit('/').next().unwrap_or(j).to_string())
            .chain(std::iter::once("gripper".to_string()))
            .collect(),
    }
}

impl Dims {
    /// The layout of `rig`'s vectors in `space`.
    pub fn new(rig: &Rig, space: ActionSpace) -> Self {
        let arms = rig
            .arms
            .iter()
            .enumerate()
            .map(|(i, a)| ArmDims {
                range: space.arm_range(rig, i),
                labels: labels(a, space),
                kin: (space == ActionSpace::Joints)
                    .then(|| ArmKinematics::new(a).ok())
                    .flatten(),
            })
            .collect();
        Dims {
            space,
            arms,
            dim: space.dim(rig),
        }
    }

    /// Whether vectors of `n` values are this layout's.
    pub fn fits(&self, n: usize) -> bool {
        n == self.dim && !self.arms.is_empty()
    }

    /// Arm `arm`'s TCP position in each row, as a line strip (rows too short are skipped).
    pub fn tcp_strip(&self, rows: &[Vec<f32>], arm: usize) -> Vec<[f32; 3]> {
        let Some(a) = self.arms.get(arm) else {
            return Vec::new();
        };
        rows.iter()
            .filter_map(|r| r.get(a.range.clone()))
            .filter_map(|v| match (self.space, &a.kin) {
                (ActionSpace::Tcp, _) => Some([v[0], v[1], v[2]]),
                (ActionSpace::Joints, Some(kin)) => {
                    let q: Vec<f64> = v[..v.len() - 1].iter().map(|&x| f64::from(x)).collect();
                    let p = kin.base_from_tcp(&q).ok()?.w_axis;
                    Some([p.x as f32, p.y as f32, p.z as f32])
                }
                (ActionSpace::Joints, None) => None,
            })
            .collect()
    }
}
