//! An arm's forward kinematics as the converter uses them: the built-in model of the rig's
//! `model` (or the URDF chain it names) to the flange, then the TCP offset (`tcp_xyz_rpy`, else
//! the model's default tool centre point), giving the 6-D TCP pose `[x, y, z, roll, pitch, yaw]`
//! in the arm's base frame.

use glam::DMat4;
use scaledp_schema::kinematics::{pose6_from_transform, rotation_from_rpy};
use scaledp_schema::rig::Arm;

use crate::error::{Error, Result};

/// The chain to the flange: a built-in model or a URDF chain.
#[derive(Debug, Clone)]
enum Chain {
    Builtin(scaledp_schema::RobotModel),
    Urdf(crate::urdf::UrdfChain),
}

/// An arm's kinematics from joint positions (rig order, rad or m) to its TCP pose.
#[derive(Debug, Clone)]
pub struct ArmKinematics {
    chain: Chain,
    flange_from_tcp: DMat4,
}

impl ArmKinematics {
    /// The kinematics of `arm`: its URDF chain when it names one (whose joints must be the
    /// rig's, in order), else its built-in model; its `tcp_xyz_rpy` offset, else the model's
    /// default TCP (identity for a URDF chain).
    pub fn new(arm: &Arm) -> Result<Self> {
        let flange_from_tcp = match arm.tcp_xyz_rpy {
            Some([x, y, z, r, p, yw]) => {
                DMat4::from_translation(glam::DVec3::new(x, y, z))
                    * DMat4::from_mat3(rotation_from_rpy([r, p, yw]))
            }
            None if arm.urdf.is_some() => DMat4::IDENTITY,
            None => arm.model.default_flange_from_tcp(),
        };
        let chain = match &arm.urdf {
            Some(u) => {
                let chain = crate::urdf::UrdfChain::from_file(&u.path, &u.base_link, &u.tip_link)?;
                if chain.joint_names() != arm.joint_names.as_slice() {
                    return Err(Error::input(
                        &u.path,
                        format!(
                            "arm '{}': URDF joints {:?} differ from the rig's {:?}",
                            arm.name,
                            chain.joint_names(),
                            arm.joint_names
                        ),
                    ));
                }
                Chain::Urdf(chain)
            }
            None => Chain::Builtin(arm.model),
        };
        Ok(Self {
            chain,
            flange_from_tcp,
        })
    }

    /// The transform from the arm's base frame to its TCP at joint positions `q`.
    pub fn base_from_tcp(&self, q: &[f64]) -> std::result::Result<DMat4, String> {
        let flange = match &self.chain {
            Chain::Builtin(m) => m.base_from_flange(q).map_err(|e| e.to_string())?,
            Chain::Urdf(c) => c.base_from_tip(q).map_err(|e| e.to_string())?,
        };
        Ok(flange * self.flange_from_tcp)
    }

    /// The TCP pose `[x, y, z, roll, pitch, yaw]` (m, rad; R = Rz(yaw)·Ry(pitch)·Rx(roll)) in
    /// the base frame at joint positions `q`. Angles are in (−π, π]: unwrap a sequence with
    /// [`scaledp_schema::kinematics::unwrap_angles`] as the converter does along an episode.
    pub fn tcp_pose(&self, q: &[f64]) -> std::result::Result<[f64; 6], String> {
        self.base_from_tcp(q).map(pose6_from_transform)
    }
}

/// `a + w (b − a)` per element: the joint interpolation the converter uses between the two
/// samples around a tick.
pub fn lerp(a: &[f64], b: &[f64], w: f64) -> Vec<f64> {
    a.iter().zip(b).map(|(a, b)| a + w * (b - a)).collect()
}
