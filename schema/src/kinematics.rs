//! Forward kinematics of the arms scaledp knows: from their published DH parameters, and for
//! the simulation benchmarks' arms from the simulators' own models ([`crate::chains`]).
//!
//! Frames: `base` is the robot's base link (`fr3_link0`, UR `base_link` in the DH convention,
//! i.e. rotated 180° about z from the ROS `base_link` of ur_description; MetaWorld's world frame
//! for its Sawyer; the arm's root body for gym-aloha's ViperX); `flange` is the last DH frame
//! (`fr3_link8`, UR `tool0`), MetaWorld's `hand` body, the ViperX's `gripper_link`. Tool centre
//! points are added by the caller.

use std::f64::consts::FRAC_PI_2;
use std::fmt;

use glam::{DMat3, DMat4, DVec3};
use serde::{Deserialize, Serialize};

use crate::chains;
use crate::error::{Error, Result};

/// An arm model with built-in kinematics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RobotModel {
    /// Franka Research 3.
    Fr3,
    /// Franka Emika Panda.
    Panda,
    /// Universal Robots UR5 (CB3).
    Ur5,
    /// Universal Robots UR5e.
    Ur5e,
    /// Rethink Sawyer, as MetaWorld simulates it.
    Sawyer,
    /// Trossen ViperX 300 6DOF, as gym-aloha simulates it (ALOHA's arms).
    Vx300s,
}

impl fmt::Display for RobotModel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Fr3 => "fr3",
            Self::Panda => "panda",
            Self::Ur5 => "ur5",
            Self::Ur5e => "ur5e",
            Self::Sawyer => "sawyer",
            Self::Vx300s => "vx300s",
        })
    }
}

/// Franka modified DH rows (a, d, alpha), joints 1–7 then the flange (θ = 0).
const FRANKA_MDH: [(f64, f64, f64); 8] = [
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -FRAC_PI_2),
    (0.0, 0.316, FRAC_PI_2),
    (0.0825, 0.0, FRAC_PI_2),
    (-0.0825, 0.384, -FRAC_PI_2),
    (0.0, 0.0, FRAC_PI_2),
    (0.088, 0.0, FRAC_PI_2),
    (0.0, 0.107, 0.0),
];

/// UR standard DH rows (d, a, alpha).
const UR5_DH: [(f64, f64, f64); 6] = [
    (0.089159, 0.0, FRAC_PI_2),
    (0.0, -0.425, 0.0),
    (0.0, -0.39225, 0.0),
    (0.10915, 0.0, FRAC_PI_2),
    (0.09465, 0.0, -FRAC_PI_2),
    (0.0823, 0.0, 0.0),
];
const UR5E_DH: [(f64, f64, f64); 6] = [
    (0.1625, 0.0, FRAC_PI_2),
    (0.0, -0.425, 0.0),
    (0.0, -0.3922, 0.0),
    (0.1333, 0.0, FRAC_PI_2),
    (0.0997, 0.0, -FRAC_PI_2),
    (0.0996, 0.0, 0.0),
];

fn rot_x(a: f64) -> DMat4 {
    DMat4::from_rotation_x(a)
}
fn rot_z(a: f64) -> DMat4 {
    DMat4::from_rotation_z(a)
}
fn trans(x: f64, y: f64, z: f64) -> DMat4 {
    DMat4::from_translation(DVec3::new(x, y, z))
}

impl RobotModel {
    /// Number of arm joints.
    pub fn dof(self) -> usize {
        match self {
            Self::Fr3 | Self::Panda => 7,
            Self::Ur5 | Self::Ur5e => 6,
            Self::Sawyer => chains::SAWYER.dof(),
            Self::Vx300s => chains::VX300S.dof(),
        }
    }

    /// Joint position limits (rad), lower and upper, per joint.
    pub fn joint_limits(self) -> &'static [(f64, f64)] {
        const PANDA: [(f64, f64); 7] = [
            (-2.8973, 2.8973),
            (-1.7628, 1.7628),
            (-2.8973, 2.8973),
            (-3.0718, -0.0698),
            (-2.8973, 2.8973),
            (-0.0175, 3.7525),
            (-2.8973, 2.8973),
        ];
        const FR3: [(f64, f64); 7] = [
            (-2.7437, 2.7437),
            (-1.7837, 1.7837),
            (-2.9007, 2.9007),
            (-3.0421, -0.1518),
            (-2.8065, 2.8065),
            (0.5445, 4.5169),
            (-3.0159, 3.0159),
        ];
        const TAU: f64 = std::f64::consts::TAU;
        const UR: [(f64, f64); 6] = [
            (-TAU, TAU),
            (-TAU, TAU),
            (-std::f64::consts::PI, std::f64::consts::PI),
            (-TAU, TAU),
            (-TAU, TAU),
            (-TAU, TAU),
        ];
        // The MJCF joint ranges.
        const SAWYER: [(f64, f64); 7] = [
            (-3.0503, 3.0503),
            (-3.8, -0.5),
            (-3.0426, 3.0426),
            (-3.0439, 3.0439),
            (-2.9761, 2.9761),
            (-2.9761, 2.9761),
            (-4.7124, 4.7124),
        ];
        const VX300S: [(f64, f64); 6] = [
            (-3.14158, 3.14158),
            (-1.85005, 1.25664),
            (-1.76278, 1.6057),
            (-3.14158, 3.14158),
            (-1.8675, 2.23402),
            (-3.14158, 3.14158),
        ];
        match self {
            Self::Panda => &PANDA,
            Self::Fr3 => &FR3,
            Self::Ur5 | Self::Ur5e => &UR,
            Self::Sawyer => &SAWYER,
            Self::Vx300s => &VX300S,
        }
    }

    /// Transforms `base_from_joint_i` for every DH frame, the last being `base_from_flange`.
    pub fn frames(self, q: &[f64]) -> Result<Vec<DMat4>> {
        if q.len() != self.dof() {
            return Err(Error::Kinematics(format!(
                "{self} needs {} joint positions, got {}",
                self.dof(),
                q.len()
            )));
        }
        if let Some(i) = q.iter().position(|x| !x.is_finite()) {
            return Err(Error::Kinematics(format!(
                "{self} joint {} is not finite ({})",
                i + 1,
                q[i]
            )));
        }
        let mut t = DMat4::IDENTITY;
        let mut out = Vec::with_capacity(q.len() + 1);
        match self {
            Self::Fr3 | Self::Panda => {
                for (i, &(a, d, alpha)) in FRANKA_MDH.iter().enumerate() {
                    let theta = q.get(i).copied().unwrap_or(0.0);
                    t = t * rot_x(alpha) * trans(a, 0.0, 0.0) * rot_z(theta) * trans(0.0, 0.0, d);
                    out.push(t);
                }
            }
            Self::Ur5 | Self::Ur5e => {
                let dh = if self == Self::Ur5 { &UR5_DH } else { &UR5E_DH };
                for (&(d, a, alpha), &theta) in dh.iter().zip(q) {
                    t = t * rot_z(theta) * trans(0.0, 0.0, d) * trans(a, 0.0, 0.0) * rot_x(alpha);
                    out.push(t);
                }
            }
            Self::Sawyer => out = chains::SAWYER.frames(q),
            Self::Vx300s => out = chains::VX300S.frames(q),
        }
        Ok(out)
    }

    /// Where joint `i` turns, for a model given as an MJCF chain (Sawyer, ViperX): its origin and
    /// axis in the base frame, from the `frames` of [`Self::frames`]. `None` for the DH models
    /// (their axes follow from the DH convention) or a bad index.
    pub fn joint_axis(self, i: usize, frames: &[DMat4]) -> Option<(DVec3, DVec3)> {
        let chain = match self {
            Self::Sawyer => &chains::SAWYER,
            Self::Vx300s => &chains::VX300S,
            _ => return None,
        };
        let (f, j) = (frames.get(i)?, chain.joints.get(i)?);
        Some((
            f.w_axis.truncate(),
            f.transform_vector3(DVec3::from_array(j.axis)),
        ))
    }

    /// `base_from_flange` for joint positions `q` (rad), in the model's joint order.
    pub fn base_from_flange(self, q: &[f64]) -> Result<DMat4> {
        self.frames(q).map(|f| f[f.len() - 1])
    }

    /// The usual `flange_from_tcp` for this arm's standard gripper: the Franka Hand's fingertip
    /// centre (0.1034 m along z, −45° about z); identity for the others (UR `tool0`, MetaWorld's
    /// `hand`, the ViperX's `gripper_link`).
    pub fn default_flange_from_tcp(self) -> DMat4 {
        match self {
            Self::Fr3 | Self::Panda => {
                trans(0.0, 0.0, 0.1034) * rot_z(-std::f64::consts::FRAC_PI_4)
            }
            Self::Ur5 | Self::Ur5e | Self::Sawyer | Self::Vx300s => DMat4::IDENTITY,
        }
    }
}

/// Roll, pitch, yaw (rad) of a rotation with ROS's convention R = Rz(yaw)·Ry(pitch)·Rx(roll).
pub fn rpy_from_rotation(r: DMat3) -> [f64; 3] {
    // Column-major: r.col(c)[row].
    let (r00, r10, r20) = (r.col(0)[0], r.col(0)[1], r.col(0)[2]);
    let cos_pitch = r00.hypot(r10);
    // atan2 keeps full precision near ±π/2, where asin(−r20) loses digits.
    let pitch = (-r20).atan2(cos_pitch);
    if cos_pitch > 1e-12 {
        let yaw = r10.atan2(r00);
        // Roll from Rz(−yaw)·R = Ry(pitch)·Rx(roll), whose middle row is (0, cos roll,
        // −sin roll). Unlike atan2(r21, r22) this roll fits the yaw actually returned, so the
        // angles rebuild R to rounding error even where cos(pitch) is tiny and yaw is poorly
        // conditioned (tests/tests/fk_reference.rs checks this next to gimbal lock).
        let (sy, cy) = yaw.sin_cos();
        let roll = (sy * r.col(2)[0] - cy * r.col(2)[1]).atan2(cy * r.col(1)[1] - sy * r.col(1)[0]);
        [roll, pitch, yaw]
    } else {
        // Gimbal lock: only roll − yaw (or roll + yaw) is defined; put it all in yaw.
        let yaw = (-r.col(1)[0]).atan2(r.col(1)[1]);
        [0.0, pitch, yaw]
    }
}

/// The rotation R = Rz(yaw)·Ry(pitch)·Rx(roll).
pub fn rotation_from_rpy(rpy: [f64; 3]) -> DMat3 {
    DMat3::from_rotation_z(rpy[2]) * DMat3::from_rotation_y(rpy[1]) * DMat3::from_rotation_x(rpy[0])
}

/// x, y, z, roll, pitch, yaw of a transform.
pub fn pose6_from_transform(t: DMat4) -> [f64; 6] {
    let p = t.w_axis.truncate();
    let [r, pi, y] = rpy_from_rotation(DMat3::from_mat4(t));
    [p.x, p.y, p.z, r, pi, y]
}

/// Unwraps an angle sequence in place so consecutive values never jump by more than π.
pub fn unwrap_angles(angles: &mut [f64]) {
    use std::f64::consts::{PI, TAU};
    for i in 1..angles.len() {
        let d = angles[i] - angles[i - 1];
        angles[i] -= TAU * ((d + PI) / TAU).floor();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn franka_zero_pose_matches_the_dh_table() {
        // At q = 0 the flange sits at x = 0.088, z = 0.333 + 0.316 + 0.384 − 0.107, pointing down.
        let t = RobotModel::Fr3.base_from_flange(&[0.0; 7]).unwrap();
        let p = t.w_axis.truncate();
        assert!((p - DVec3::new(0.088, 0.0, 0.926)).length() < 1e-12, "{p}");
        assert!((t.z_axis.truncate() - DVec3::new(0.0, 0.0, -1.0)).length() < 1e-12);
    }

    #[test]
    fn ur5_zero_pose_matches_the_dh_table() {
        let t = RobotModel::Ur5.base_from_flange(&[0.0; 6]).unwrap();
        let p = t.w_axis.truncate();
        let want = DVec3::new(-0.425 - 0.39225, -(0.10915 + 0.0823), 0.089159 - 0.09465);
        assert!((p - want).length() < 1e-12, "{p} vs {want}");
    }

    #[test]
    fn rpy_round_trips_and_rejects_bad_input() {
        for rpy in [[0.1, -0.4, 2.9], [-3.0, 1.2, -0.2], [0.0, 0.0, 0.0]] {
            let back = rpy_from_rotation(rotation_from_rpy(rpy));
            for (a, b) in rpy.iter().zip(back) {
                assert!((a - b).abs() < 1e-12, "{rpy:?} -> {back:?}");
            }
        }
        assert!(RobotModel::Ur5.base_from_flange(&[0.0; 7]).is_err());
        assert!(RobotModel::Fr3.base_from_flange(&[f64::NAN; 7]).is_err());
    }

    #[test]
    fn unwrapping_crosses_pi() {
        let mut a = [3.0, 3.13, -3.13, -3.0, 3.1];
        unwrap_angles(&mut a);
        for w in a.windows(2) {
            assert!((w[1] - w[0]).abs() < 0.5, "{a:?}");
        }
        assert!((a[2] - (-3.13 + std::f64::consts::TAU)).abs() < 1e-12);
    }
}
