//! Kinematic chains taken from simulators' MJCF models, for the arms of the simulation
//! benchmarks: each joint's body placed in its parent by a translation and a rotation (the
//! compiled model's `body_pos` and `body_quat`, w x y z), then rotated by the joint angle about
//! its axis; fixed bodies after the last joint lead to the flange.
//!
//! - Rethink Sawyer as MetaWorld 3.1 builds it (`metaworld/assets/sawyer_xyz/`): the base
//!   frame is MetaWorld's world frame (`base` and `right_arm_base_link` sit at its origin),
//!   joints `right_j0` … `right_j6`, flange = MetaWorld's `hand` body (whose position is the
//!   first three values of a MetaWorld observation).
//! - Trossen ViperX 300 6DOF (`vx300s`) as gym-aloha 0.1.5 builds it: the base frame is the
//!   arm's root body (`vx300s_left` / `vx300s_right`), joints waist, shoulder, elbow,
//!   forearm_roll, wrist_angle, wrist_rotate, flange = `gripper_link`.

use glam::{DMat4, DQuat, DVec3};

/// One joint: its body's placement in the parent body, then a rotation about `axis`.
pub(crate) struct Joint {
    pub pos: [f64; 3],
    pub quat: [f64; 4],
    pub axis: [f64; 3],
}

/// A chain: joints in order, then fixed placements to the flange.
pub(crate) struct Chain {
    pub joints: &'static [Joint],
    pub tip: &'static [([f64; 3], [f64; 4])],
}

const FRAC_1_SQRT_2: f64 = std::f64::consts::FRAC_1_SQRT_2;
const I: [f64; 4] = [1.0, 0.0, 0.0, 0.0];
const Z: [f64; 3] = [0.0, 0.0, 1.0];
const Y: [f64; 3] = [0.0, 1.0, 0.0];
const X: [f64; 3] = [1.0, 0.0, 0.0];

/// MetaWorld's Sawyer: bodies `right_l0` … `right_l6` (each with its joint about z), then
/// `right_hand` and `hand`.
pub(crate) const SAWYER: Chain = Chain {
    joints: &[
        Joint {
            pos: [0.0, 0.0, 0.08],
            quat: I,
            axis: Z,
        },
        Joint {
            pos: [0.081, 0.05, 0.237],
            quat: [0.5, -0.5, 0.5, 0.5],
            axis: Z,
        },
        Joint {
            pos: [0.0, -0.14, 0.1425],
            quat: [FRAC_1_SQRT_2, FRAC_1_SQRT_2, 0.0, 0.0],
            axis: Z,
        },
        Joint {
            pos: [0.0, -0.042, 0.26],
            quat: [FRAC_1_SQRT_2, -FRAC_1_SQRT_2, 0.0, 0.0],
            axis: Z,
        },
        Joint {
            pos: [0.0, -0.125, -0.1265],
            quat: [FRAC_1_SQRT_2, FRAC_1_SQRT_2, 0.0, 0.0],
            axis: Z,
        },
        Joint {
            pos: [0.0, 0.031, 0.275],
            quat: [FRAC_1_SQRT_2, -FRAC_1_SQRT_2, 0.0, 0.0],
            axis: Z,
        },
        Joint {
            pos: [0.0, -0.11, 0.1053],
            quat: [
                0.061_624_810_014_431_77,
                0.061_630_010_015_276_8,
                -0.704_416_114_472_192_5,
                0.704_416_114_472_192_5,
            ],
            axis: Z,
        },
    ],
    tip: &[
        ([0.0, 0.0, 0.0245], [FRAC_1_SQRT_2, 0.0, 0.0, FRAC_1_SQRT_2]),
        ([0.0, 0.0, 0.12], [-FRAC_1_SQRT_2, 0.0, FRAC_1_SQRT_2, 0.0]),
    ],
};

/// gym-aloha's ViperX 300 6DOF: `shoulder_link` … `gripper_link`.
pub(crate) const VX300S: Chain = Chain {
    joints: &[
        Joint {
            pos: [0.0, 0.0, 0.079],
            quat: I,
            axis: Z,
        },
        Joint {
            pos: [0.0, 0.0, 0.04805],
            quat: I,
            axis: Y,
        },
        Joint {
            pos: [0.05955, 0.0, 0.3],
            quat: I,
            axis: Y,
        },
        Joint {
            pos: [0.2, 0.0, 0.0],
            quat: I,
            axis: X,
        },
        Joint {
            pos: [0.1, 0.0, 0.0],
            quat: I,
            axis: Y,
        },
        Joint {
            pos: [0.069744, 0.0, 0.0],
            quat: I,
            axis: X,
        },
    ],
    tip: &[],
};

fn placement(pos: [f64; 3], q: [f64; 4]) -> DMat4 {
    let rot = DQuat::from_xyzw(q[1], q[2], q[3], q[0]).normalize();
    DMat4::from_rotation_translation(rot, DVec3::from_array(pos))
}

impl Chain {
    /// Degrees of freedom.
    pub fn dof(&self) -> usize {
        self.joints.len()
    }

    /// `base_from_joint_i` after each joint's rotation, then `base_from_flange` last.
    pub fn frames(&self, q: &[f64]) -> Vec<DMat4> {
        let mut t = DMat4::IDENTITY;
        let mut out = Vec::with_capacity(self.joints.len() + 1);
        for (j, &angle) in self.joints.iter().zip(q) {
            let axis = DVec3::from_array(j.axis);
            t = t * placement(j.pos, j.quat) * DMat4::from_axis_angle(axis, angle);
            out.push(t);
        }
        for &(pos, quat) in self.tip {
            t *= placement(pos, quat);
        }
        out.push(t);
        out
    }
}
