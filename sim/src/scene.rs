//! The cell's fixed geometry, the same under every seed: where each arm stands, its tool
//! frames, its rest posture, the table and the patch of table each arm works on.
//!
//! Arms stand along the world y axis, 0.7 m apart (the first at +y, on the left seen from the
//! front camera), facing world +x; the table top is the plane z = 0, level with the bases.
//! UR bases are turned half a turn so their DH base's −x (where a UR reaches with the shoulder
//! pan at zero) faces +x.

use glam::{DMat3, DMat4, DVec2, DVec3};
use scaledp_schema::kinematics::rotation_from_rpy;
use scaledp_schema::rig::{Arm, Rig};
use scaledp_schema::RobotModel;

use crate::ik;

/// Half the cube's edge (m): a 4.5 cm cube.
pub const CUBE_HALF_M: f64 = 0.0225;
/// Height of the table top (m).
pub const TABLE_Z_M: f64 = 0.0;
/// Tilt (rad) of the nominal tool orientation from straight down. A tool pointing straight down
/// has roll ±π, where ROS roll/pitch/yaw wrap: demonstrations would land on either branch. Tilted
/// by 0.2 rad its roll stays near π − 0.2, well clear of the wrap.
pub const TOOL_TILT_RAD: f64 = 0.2;

/// One arm's place in the cell.
#[derive(Debug, Clone)]
pub struct ArmLayout {
    /// The rig's arm.
    pub arm: Arm,
    /// Where its base stands.
    pub world_from_base: DMat4,
    /// Its TCP (what commands and the converter's state refer to): the rig's `tcp_xyz_rpy`, else
    /// the model's default (Franka Hand TCP, UR `tool0`).
    pub flange_from_tcp: DMat4,
    /// Where the fingertips close (the grasp frame).
    pub flange_from_fingertips: DMat4,
    /// Joint positions at rest, the fingertips above the middle of its workspace.
    pub home_q: Vec<f64>,
    /// The tool orientation (world) an operator grasps with: z down, tilted by [`TOOL_TILT_RAD`].
    pub grasp_rotation: DMat3,
    /// Middle of the patch of table its cube and target are drawn from (world, on the table).
    pub region_center: DVec3,
    /// Half extents (x, y) of that patch (m).
    pub region_half: DVec2,
}

impl ArmLayout {
    /// `fingertips_from_tcp`: turns a fingertip pose into the TCP pose a controller is sent.
    pub fn fingertips_from_tcp(&self) -> DMat4 {
        self.flange_from_fingertips.inverse() * self.flange_from_tcp
    }
    /// `base_from_flange` at `q` (identity for invalid `q`).
    pub fn base_from_flange(&self, q: &[f64]) -> DMat4 {
        self.arm
            .model
            .base_from_flange(q)
            .unwrap_or(DMat4::IDENTITY)
    }
    /// The fingertips' pose in the world at `q`.
    pub fn world_from_fingertips(&self, q: &[f64]) -> DMat4 {
        self.world_from_base * self.base_from_flange(q) * self.flange_from_fingertips
    }
}

/// The fixed geometry of a rig's simulated cell.
#[derive(Debug, Clone)]
pub struct Scene {
    arms: Vec<ArmLayout>,
}

/// The rig's TCP offset, by the converter's rule: `tcp_xyz_rpy` when set, else the model's
/// default (URDF chains are not simulated; their arms use the built-in model).
pub fn flange_from_tcp(arm: &Arm) -> DMat4 {
    match arm.tcp_xyz_rpy {
        Some([x, y, z, r, p, yw]) => {
            DMat4::from_translation(DVec3::new(x, y, z))
                * DMat4::from_mat3(rotation_from_rpy([r, p, yw]))
        }
        None => arm.model.default_flange_from_tcp(),
    }
}

/// Where the simulated fingertips close: the Franka Hand's TCP, or 15 cm ahead of a UR's tool0
/// for a Robotiq 2F-85.
pub fn flange_from_fingertips(arm: &Arm) -> DMat4 {
    match arm.model {
        RobotModel::Fr3 | RobotModel::Panda => RobotModel::Fr3.default_flange_from_tcp(),
        RobotModel::Ur5 | RobotModel::Ur5e => DMat4::from_translation(DVec3::new(0.0, 0.0, 0.15)),
        // The benchmarks' arms (their own simulators run them): the flange itself.
        RobotModel::Sawyer | RobotModel::Vx300s => DMat4::IDENTITY,
    }
}

/// A posture near which each model reaches down to the table in front of it.
fn seed_posture(model: RobotModel) -> Vec<f64> {
    match model {
        RobotModel::Fr3 | RobotModel::Panda => vec![0.0, -0.3, 0.0, -2.2, 0.0, 1.95, 0.785],
        RobotModel::Ur5 | RobotModel::Ur5e => vec![0.0, -1.9, 1.9, -1.57, -1.57, 0.0],
        // MetaWorld's and ALOHA's start postures.
        RobotModel::Sawyer => vec![1.89, -0.58, -0.98, 1.64, 0.94, 1.04, 2.29],
        RobotModel::Vx300s => vec![0.0, -0.96, 1.16, 0.0, -0.3, 0.0],
    }
}

impl Scene {
    /// The cell of `rig`.
    pub fn new(rig: &Rig) -> Self {
        let n = rig.arms.len();
        let arms = rig
            .arms
            .iter()
            .enumerate()
            .map(|(i, arm)| {
                let y = ((n as f64 - 1.0) / 2.0 - i as f64) * 0.7;
                let turn = match arm.model {
                    RobotModel::Ur5 | RobotModel::Ur5e => std::f64::consts::PI,
                    _ => 0.0,
                };
                let world_from_base = DMat4::from_translation(DVec3::new(0.0, y, TABLE_Z_M))
                    * DMat4::from_rotation_z(turn);
                // Yaw (world) chosen near each model's seed posture, so reaching it needs no wrist
                // turn: the Franka Hand's fingers close along y as in Franka's ready pose (TCP yaw
                // 0 in the base frame), the Robotiq's along x (TCP yaw π/2 in the DH base frame).
                // Both are far from the ±π wrap, like the roll.
                let yaw = match arm.model {
                    RobotModel::Ur5 | RobotModel::Ur5e => -std::f64::consts::FRAC_PI_2,
                    _ => 0.0,
                };
                let grasp_rotation = DMat3::from_rotation_z(yaw)
                    * DMat3::from_rotation_x(std::f64::consts::PI - TOOL_TILT_RAD);
                // Two arms work on the inner halves of their sides, so one camera sees both.
                let inward = if n > 1 { -y.signum() * 0.06 } else { 0.0 };
                let region_center = DVec3::new(0.47, y + inward, TABLE_Z_M);
                let region_half = if n > 1 {
                    DVec2::new(0.08, 0.10)
                } else {
                    DVec2::new(0.09, 0.15)
                };
                let mut layout = ArmLayout {
                    arm: arm.clone(),
                    world_from_base,
                    flange_from_tcp: flange_from_tcp(arm),
                    flange_from_fingertips: flange_from_fingertips(arm),
                    home_q: seed_posture(arm.model),
                    grasp_rotation,
                    region_center,
                    region_half,
                };
                let home = layout.home_fingertips();
                let target_tcp = world_from_base.inverse() * home * layout.fingertips_from_tcp();
                let (q, _, _) = ik::solve(
                    arm.model,
                    &layout.flange_from_tcp,
                    &target_tcp,
                    &seed_posture(arm.model),
                    600,
                );
                layout.home_q = q;
                layout
            })
            .collect();
        Self { arms }
    }

    /// The arms, in rig order.
    pub fn arms(&self) -> &[ArmLayout] {
        &self.arms
    }

    /// Middle of all work regions (what the front camera looks at).
    pub fn workspace_center(&self) -> DVec3 {
        if self.arms.is_empty() {
            return DVec3::new(0.47, 0.0, TABLE_Z_M);
        }
        self.arms.iter().map(|a| a.region_center).sum::<DVec3>() / self.arms.len() as f64
    }

    /// Middle of the arms' bases.
    pub fn bases_center(&self) -> DVec3 {
        if self.arms.is_empty() {
            return DVec3::ZERO;
        }
        self.arms
            .iter()
            .map(|a| a.world_from_base.w_axis.truncate())
            .sum::<DVec3>()
            / self.arms.len() as f64
    }
}

impl ArmLayout {
    /// The fingertip pose at rest: 28 cm above the near edge of the work region, grasp
    /// orientation.
    pub fn home_fingertips(&self) -> DMat4 {
        let p = self.region_center + DVec3::new(-0.06, 0.0, 0.28);
        DMat4::from_translation(p) * DMat4::from_mat3(self.grasp_rotation)
    }
}

#[cfg(test)]
mod tests {
    use scaledp_schema::kinematics::pose6_from_transform;

    use super::*;

    #[test]
    fn every_shipped_rig_rests_at_its_home_pose_with_roll_clear_of_the_wrap() {
        for name in Rig::builtin_names() {
            let rig = Rig::builtin(name).unwrap();
            let scene = Scene::new(&rig);
            for a in scene.arms() {
                let at = a.world_from_fingertips(&a.home_q);
                let want = a.home_fingertips();
                let (dp, dr) = ik::pose_error(&at, &want);
                assert!(
                    dp.length() < 1e-4 && dr.length() < 1e-3,
                    "{name}: {dp} {dr}"
                );
                for (x, (lo, hi)) in a.home_q.iter().zip(a.arm.model.joint_limits()) {
                    assert!(
                        (lo + 0.1..=hi - 0.1).contains(x),
                        "{name}: {x} near a limit"
                    );
                }
                // The TCP's roll in the base frame (the converter's state) is π − tilt.
                let tcp = a.base_from_flange(&a.home_q) * a.flange_from_tcp;
                let roll = pose6_from_transform(tcp)[3];
                let want_roll = std::f64::consts::PI - TOOL_TILT_RAD;
                assert!((roll - want_roll).abs() < 0.01, "{name}: roll {roll}");
            }
        }
    }
}
