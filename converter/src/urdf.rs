//! Forward kinematics of any serial chain in a URDF, for arms without built-in DH tables
//! (`scaledp_schema::kinematics::RobotModel`) or to use a rig's own calibrated URDF.
//!
//! Parsing is done by `urdf-rs` (it also handles URDF 1.1 `quat_xyzw` origins); the chain is
//! the path of joints from `base_link` down to `tip_link`, found by walking parent links up
//! from the tip. Each joint contributes `T(origin) · motion(q)` with the URDF conventions:
//! origin rpy is fixed-axis X, Y, Z (R = Rz(yaw)·Ry(pitch)·Rx(roll)), the axis is given in the
//! joint frame (normalized; default 1 0 0), revolute/continuous joints rotate about it and
//! prismatic joints translate along it.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{DMat3, DMat4, DVec3};
use urdf_rs::JointType;

use crate::error::{Error, Result};

/// What one joint of the chain does with its joint position.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Motion {
    /// No joint position (URDF `fixed`).
    Fixed,
    /// Rotation about this unit axis (URDF `revolute` and `continuous`).
    Revolute(DVec3),
    /// Translation along this unit axis (URDF `prismatic`).
    Prismatic(DVec3),
}

/// One joint of the chain: `parent_from_child = origin · motion(q)`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Step {
    origin: DMat4,
    motion: Motion,
}

/// A serial chain `base_link → tip_link` of a URDF, ready for forward kinematics.
#[derive(Debug, Clone, PartialEq)]
pub struct UrdfChain {
    source: PathBuf,
    steps: Vec<Step>,
    joint_names: Vec<String>,
}

impl UrdfChain {
    /// Reads the URDF at `path` and extracts the chain from `base_link` to `tip_link`.
    pub fn from_file(path: &Path, base_link: &str, tip_link: &str) -> Result<Self> {
        let xml = std::fs::read_to_string(path).map_err(Error::io(path))?;
        Self::from_xml(&xml, base_link, tip_link, path)
    }

    /// Parses URDF text and extracts the chain from `base_link` to `tip_link`; `source` only
    /// names the file in errors.
    pub fn from_xml(xml: &str, base_link: &str, tip_link: &str, source: &Path) -> Result<Self> {
        let bad = |reason: String| Error::input(source, reason);
        let robot =
            urdf_rs::read_from_string(xml).map_err(|e| bad(format!("not a valid URDF: {e}")))?;
        for link in [base_link, tip_link] {
            if !robot.links.iter().any(|l| l.name == link) {
                return Err(bad(format!(
                    "URDF robot {:?} has no link {link:?}",
                    robot.name
                )));
            }
        }
        // Each link has at most one parent joint in a URDF tree.
        let mut parent_joint: HashMap<&str, &urdf_rs::Joint> = HashMap::new();
        for j in &robot.joints {
            if let Some(other) = parent_joint.insert(j.child.link.as_str(), j) {
                return Err(bad(format!(
                    "link {:?} is the child of two joints ({:?} and {:?}): not a tree",
                    j.child.link, other.name, j.name
                )));
            }
        }
        // Walk up from the tip; the joints come out tip → base.
        let mut path = Vec::new();
        let mut link = tip_link;
        while link != base_link {
            let Some(j) = parent_joint.get(link) else {
                return Err(bad(format!(
                    "link {tip_link:?} is not below {base_link:?}: walking up from it ends at \
                     root link {link:?}"
                )));
            };
            if path.len() >= robot.joints.len() {
                return Err(bad(format!(
                    "the joints above link {tip_link:?} form a cycle"
                )));
            }
            path.push(*j);
            link = j.parent.link.as_str();
        }
        path.reverse();

        let mut steps = Vec::with_capacity(path.len());
        let mut joint_names = Vec::new();
        for j in path {
            let step = step_of(j).map_err(|reason| bad(format!("joint {:?}: {reason}", j.name)))?;
            if step.motion != Motion::Fixed {
                joint_names.push(j.name.clone());
            }
            steps.push(step);
        }
        Ok(Self {
            source: source.to_path_buf(),
            steps,
            joint_names,
        })
    }

    /// The movable joints of the chain, base → tip; `q` of [`Self::base_from_tip`] follows
    /// this order.
    pub fn joint_names(&self) -> &[String] {
        &self.joint_names
    }

    /// `base_from_tip` for joint positions `q` (rad for revolute/continuous, m for prismatic)
    /// in [`Self::joint_names`] order.
    pub fn base_from_tip(&self, q: &[f64]) -> Result<DMat4> {
        if q.len() != self.joint_names.len() {
            return Err(Error::input(
                &self.source,
                format!(
                    "the chain needs {} joint positions ({}), got {}",
                    self.joint_names.len(),
                    self.joint_names.join(", "),
                    q.len()
                ),
            ));
        }
        if let Some(i) = q.iter().position(|x| !x.is_finite()) {
            return Err(Error::input(
                &self.source,
                format!(
                    "joint position of {:?} is not finite ({})",
                    self.joint_names[i], q[i]
                ),
            ));
        }
        let mut t = DMat4::IDENTITY;
        let mut q = q.iter();
        for s in &self.steps {
            t *= s.origin;
            match s.motion {
                Motion::Fixed => {}
                Motion::Revolute(axis) => {
                    let a = q.next().copied().unwrap_or(0.0);
                    t *= DMat4::from_axis_angle(axis, a);
                }
                Motion::Prismatic(axis) => {
                    let d = q.next().copied().unwrap_or(0.0);
                    t *= DMat4::from_translation(axis * d);
                }
            }
        }
        Ok(t)
    }
}

/// The chain step of one URDF joint, or why it cannot be one.
fn step_of(j: &urdf_rs::Joint) -> std::result::Result<Step, String> {
    if let Some(m) = &j.mimic {
        return Err(format!(
            "mimic joints are not supported (it mimics {:?})",
            m.joint
        ));
    }
    let xyz = DVec3::from_array(j.origin.xyz.0);
    let [roll, pitch, yaw] = j.origin.rpy.0;
    if !xyz.is_finite() || ![roll, pitch, yaw].iter().all(|v| v.is_finite()) {
        return Err(format!(
            "origin is not finite (xyz {:?}, rpy {:?})",
            j.origin.xyz.0, j.origin.rpy.0
        ));
    }
    // URDF rpy: fixed axes X, then Y, then Z.
    let rotation =
        DMat3::from_rotation_z(yaw) * DMat3::from_rotation_y(pitch) * DMat3::from_rotation_x(roll);
    let origin = DMat4::from_translation(xyz) * DMat4::from_mat3(rotation);
    let axis = || {
        let a = DVec3::from_array(j.axis.xyz.0);
        let n = a.length();
        if n.is_finite() && n > 1e-12 {
            Ok(a / n)
        } else {
            Err(format!("axis {:?} cannot be normalized", j.axis.xyz.0))
        }
    };
    let motion = match j.joint_type {
        JointType::Fixed => Motion::Fixed,
        JointType::Revolute | JointType::Continuous => Motion::Revolute(axis()?),
        JointType::Prismatic => Motion::Prismatic(axis()?),
        ref other => {
            return Err(format!(
                "joint type {other:?} is not supported in a serial chain \
                 (revolute, continuous, prismatic and fixed are)"
            ))
        }
    };
    Ok(Step { origin, motion })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    /// A small tree: base → a (continuous about z) → b (prismatic along default x)
    /// → c (fixed, rotated), plus a side branch a → side.
    const TREE: &str = r#"<?xml version="1.0"?>
<robot name="tree">
  <link name="base"/> <link name="a"/> <link name="b"/> <link name="c"/> <link name="side"/>
  <joint name="j_a" type="continuous">
    <origin xyz="0 0 1" rpy="0 0 0"/>
    <parent link="base"/> <child link="a"/>
    <axis xyz="0 0 2"/>
  </joint>
  <joint name="j_b" type="prismatic">
    <origin xyz="1 0 0"/>
    <parent link="a"/> <child link="b"/>
    <limit lower="0" upper="1" effort="1" velocity="1"/>
  </joint>
  <joint name="j_c" type="fixed">
    <origin xyz="0 0 0.5" rpy="1.5707963267948966 0 0"/>
    <parent link="b"/> <child link="c"/>
  </joint>
  <joint name="j_side" type="revolute">
    <parent link="a"/> <child link="side"/>
    <axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
</robot>"#;

    fn chain(xml: &str, base: &str, tip: &str) -> Result<UrdfChain> {
        UrdfChain::from_xml(xml, base, tip, Path::new("robot.urdf"))
    }

    #[test]
    fn tree_chain_follows_urdf_conventions() {
        let c = chain(TREE, "base", "c").unwrap();
        assert_eq!(c.joint_names(), ["j_a", "j_b"]);
        // q_a = 90° about z, then 0.25 m along the prismatic x axis.
        let t = c.base_from_tip(&[FRAC_PI_2, 0.25]).unwrap();
        let p = t.w_axis.truncate();
        assert!((p - DVec3::new(0.0, 1.25, 1.5)).length() < 1e-12, "{p}");
        // The fixed roll of 90° maps tip z onto -y of b, which is +x of base after q_a.
        let z = t.z_axis.truncate();
        assert!((z - DVec3::new(1.0, 0.0, 0.0)).length() < 1e-12, "{z}");
        // A sub-chain and the side branch.
        assert_eq!(chain(TREE, "a", "b").unwrap().joint_names(), ["j_b"]);
        assert_eq!(
            chain(TREE, "base", "side").unwrap().joint_names(),
            ["j_a", "j_side"]
        );
        let empty = chain(TREE, "b", "b").unwrap();
        assert_eq!(empty.base_from_tip(&[]).unwrap(), DMat4::IDENTITY);
    }

    #[test]
    fn origin_rpy_is_fixed_axis_xyz() {
        let xml = r#"<robot name="r"><link name="p"/><link name="c"/>
            <joint name="j" type="fixed"><origin xyz="0.1 -0.2 0.3" rpy="0.3 -0.7 2.1"/>
            <parent link="p"/><child link="c"/></joint></robot>"#;
        let t = chain(xml, "p", "c").unwrap().base_from_tip(&[]).unwrap();
        let (r, p, y): (f64, f64, f64) = (0.3, -0.7, 2.1);
        // Rz(y)·Ry(p)·Rx(r) written out (first column and third row).
        let col0 = DVec3::new(y.cos() * p.cos(), y.sin() * p.cos(), -p.sin());
        let row2 = DVec3::new(-p.sin(), p.cos() * r.sin(), p.cos() * r.cos());
        assert!((t.x_axis.truncate() - col0).length() < 1e-12);
        assert!((t.row(2).truncate() - row2).length() < 1e-12);
        assert!((t.w_axis.truncate() - DVec3::new(0.1, -0.2, 0.3)).length() < 1e-12);
    }

    #[test]
    fn bad_chains_name_the_file() {
        let err = |r: Result<UrdfChain>| {
            let e = r.unwrap_err().to_string();
            assert!(e.starts_with("robot.urdf: "), "{e}");
            e
        };
        assert!(err(chain(TREE, "base", "nope")).contains("no link \"nope\""));
        assert!(err(chain(TREE, "side", "c")).contains("not below \"side\""));
        assert!(err(chain("<robot", "a", "b")).contains("not a valid URDF"));
        let mimic = TREE.replace(
            r#"<axis xyz="0 1 0"/>"#,
            r#"<axis xyz="0 1 0"/><mimic joint="j_a"/>"#,
        );
        assert!(err(chain(&mimic, "base", "side")).contains("mimic"));
        assert!(
            chain(&mimic, "base", "c").is_ok(),
            "mimic joint off the chain"
        );
        let zero_axis = TREE.replace(r#"xyz="0 0 2""#, r#"xyz="0 0 0""#);
        assert!(err(chain(&zero_axis, "base", "c")).contains("axis"));
        let floating = TREE.replace("prismatic", "floating");
        assert!(err(chain(&floating, "base", "c")).contains("not supported"));
        let nan = TREE.replace(r#"xyz="1 0 0""#, r#"xyz="1 NaN 0""#);
        assert!(err(chain(&nan, "base", "c")).contains("not finite"));
        let two_parents = TREE.replace(r#"<child link="side"/>"#, r#"<child link="b"/>"#);
        assert!(err(chain(&two_parents, "base", "c")).contains("two joints"));
        let cycle = TREE.replace(
            r#"<parent link="base"/> <child link="a"/>"#,
            r#"<parent link="c"/> <child link="a"/>"#,
        );
        assert!(err(chain(&cycle, "base", "c")).contains("cycle"));
    }

    #[test]
    fn bad_joint_positions_are_errors() {
        let c = chain(TREE, "base", "c").unwrap();
        let e = c.base_from_tip(&[0.0]).unwrap_err().to_string();
        assert!(
            e.contains("needs 2 joint positions (j_a, j_b), got 1"),
            "{e}"
        );
        let e = c.base_from_tip(&[0.0, f64::NAN]).unwrap_err().to_string();
        assert!(e.contains("\"j_b\" is not finite"), "{e}");
        assert!(c.base_from_tip(&[f64::INFINITY, 0.0]).is_err());
    }
}
