//! The action spaces a dataset, a checkpoint and a controller agree on.
//!
//! - [`ActionSpace::Tcp`] (the default): per arm the TCP pose in its base frame by forward
//!   kinematics, `x, y, z, roll, pitch, yaw`, then the gripper opening (m): 7 values per arm,
//!   whatever the arm's joint count. A controller sends it as a Cartesian target.
//! - [`ActionSpace::Joints`]: per arm its joint positions (rad, the rig's joint order), then the
//!   gripper opening (m): what ALOHA, LeRobot and most low-cost arms use, and what a leader arm
//!   publishes. A controller sends it as joint targets.
//!
//! `observation.state` and `action` share the space and the names ([`state_names`]).

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::rig::{Arm, Rig};

/// Which space `observation.state` and `action` are in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionSpace {
    /// 6D TCP pose (x, y, z, roll, pitch, yaw) and gripper opening per arm.
    #[default]
    Tcp,
    /// Joint positions and gripper opening per arm.
    Joints,
}

impl ActionSpace {
    /// The name on the command line and in metadata (`tcp`, `joints`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Tcp => "tcp",
            Self::Joints => "joints",
        }
    }

    /// Values per arm of `arm`.
    pub fn arm_dim(self, arm: &Arm) -> usize {
        match self {
            Self::Tcp => 7,
            Self::Joints => arm.joint_names.len() + 1,
        }
    }

    /// Where arm `index` of `rig` starts in a state or action vector, and its width.
    pub fn arm_range(self, rig: &Rig, index: usize) -> std::ops::Range<usize> {
        let start: usize = rig.arms[..index].iter().map(|a| self.arm_dim(a)).sum();
        start..start + self.arm_dim(&rig.arms[index])
    }

    /// Values of a whole state or action vector of `rig`.
    pub fn dim(self, rig: &Rig) -> usize {
        rig.arms.iter().map(|a| self.arm_dim(a)).sum()
    }

    /// What the action is, for a dataset's metadata.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Tcp => {
                "absolute end-effector pose of the next tick (the last tick of each episode is \
                 dropped), or the latest command at the tick for arms with a command topic: per \
                 arm in rig order x, y, z (m), roll, pitch, yaw (rad, ROS R = \
                 Rz(yaw)·Ry(pitch)·Rx(roll), unwrapped along the episode), gripper opening (m); \
                 observation.state is the same at the current tick"
            }
            Self::Joints => {
                "absolute joint positions of the next tick (the last tick of each episode is \
                 dropped), or the latest joint command at the tick for arms with a JointState \
                 command topic: per arm in rig order its joints (rad, rig order), gripper \
                 opening (m); observation.state is the same at the current tick"
            }
        }
    }
}

impl fmt::Display for ActionSpace {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ActionSpace {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "tcp" => Ok(Self::Tcp),
            "joints" => Ok(Self::Joints),
            other => Err(format!(
                "no action space {other:?}: tcp (6D TCP pose and gripper per arm) or joints \
                 (joint positions and gripper per arm)"
            )),
        }
    }
}

/// A joint's name in feature names: what follows its last `/` (`vx300s_left/waist` → `waist`).
fn short(joint: &str) -> &str {
    joint.rsplit('/').next().unwrap_or(joint)
}

/// State and action names of `rig` in `space`: per arm in rig order, `x, y, z, roll, pitch,
/// yaw, gripper` (tcp) or its joints' names and `gripper` (joints, LeRobot's ALOHA naming),
/// prefixed `<arm>_` when the rig has more than one arm (unless a joint's name already starts
/// so: `left_shoulder_pan_joint` stays as it is).
pub fn state_names(rig: &Rig, space: ActionSpace) -> Vec<String> {
    const TCP: [&str; 7] = ["x", "y", "z", "roll", "pitch", "yaw", "gripper"];
    let prefix = rig.arms.len() > 1;
    rig.arms
        .iter()
        .flat_map(|a| {
            let dims: Vec<&str> = match space {
                ActionSpace::Tcp => TCP.to_vec(),
                ActionSpace::Joints => a
                    .joint_names
                    .iter()
                    .map(|j| short(j))
                    .chain(std::iter::once("gripper"))
                    .collect(),
            };
            let own = format!("{}_", a.name);
            dims.into_iter()
                .map(|d| {
                    // A joint already named after its arm keeps its name.
                    if prefix && !d.starts_with(&own) {
                        format!("{own}{d}")
                    } else {
                        d.to_string()
                    }
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_ranges_follow_the_space() {
        let rig = Rig::builtin("bimanual_ur5_sim").unwrap();
        let tcp = state_names(&rig, ActionSpace::Tcp);
        assert_eq!(tcp.len(), 14);
        assert_eq!(tcp[7], "right_x");
        let joints = state_names(&rig, ActionSpace::Joints);
        assert_eq!(joints.len(), ActionSpace::Joints.dim(&rig));
        assert_eq!(joints.len(), 14);
        let last = ActionSpace::Joints.arm_range(&rig, 1);
        assert_eq!(last, 7..14);
        assert_eq!(joints[6], "left_gripper");
        assert_eq!(joints[0], "left_shoulder_pan_joint");
        assert_eq!("joints".parse::<ActionSpace>(), Ok(ActionSpace::Joints));
        assert!("pose".parse::<ActionSpace>().unwrap_err().contains("tcp"));
        let one = Rig::builtin("franka_sim").unwrap();
        assert_eq!(state_names(&one, ActionSpace::Joints).len(), 8);
        assert_eq!(state_names(&one, ActionSpace::Tcp)[0], "x");
    }
}
