//! The ROS 2 messages the simulated rig publishes and the commands it takes, built from and read
//! into world terms; the live runtime and the offline writer share them byte for byte.
//!
//! Commands, per arm:
//! - the TCP target as `geometry_msgs/msg/PoseStamped` in the arm's base frame (the converter's
//!   state convention: flange + the rig's TCP offset), as a Cartesian controller such as
//!   cartesian_motion_controller takes it on its `target_frame` topic;
//! - the gripper target as `sensor_msgs/msg/JointState` of the gripper's own finger joints, in
//!   its own units (Franka Hand: each finger = width / 2; Robotiq 2F-85: knuckle angle), as a
//!   leader gripper (GELLO, ALOHA-style leaders, VR bridges) publishes it. The drivers' own
//!   interfaces are ROS 2 actions (franka_gripper's `Move` / `Grasp`, the Robotiq driver's
//!   `GripperCommand`): goals with feedback and results, which neither zenoh-bridge-ros2dds
//!   recordings nor a policy's 10 Hz stream of targets map onto cleanly. A joint-state stream
//!   records like any topic, carries a continuous target (a trigger half pressed), and the
//!   converter reads it with the very joint names and width rule it uses for the measured
//!   gripper; a bridge to the driver's action is a few lines on the robot side.

use glam::{DMat3, DMat4, DQuat, DVec3};
use scaledp_schema::msg::{Header, Image, JointState, Point, Pose, PoseStamped, Quaternion, Time};
use scaledp_schema::rig::{Arm, Camera, CommandType, Gripper};
use scaledp_schema::{RobotModel, RosMessage};

use crate::render;
use crate::world::{ArmCommand, ArmState};

/// The frame a pose command of `arm` is expressed in: `<prefix>link0` for Franka arms (the
/// joint names' prefix, e.g. `fr3_link0`), `<prefix>base` for UR arms (ur_description's `base`,
/// the DH base frame).
pub fn base_frame_id(arm: &Arm) -> String {
    let first = arm
        .joint_names
        .first()
        .map(String::as_str)
        .unwrap_or_default();
    match arm.model {
        RobotModel::Fr3 | RobotModel::Panda => {
            let prefix = first.strip_suffix("joint1").unwrap_or("fr3_");
            format!("{prefix}link0")
        }
        RobotModel::Ur5 | RobotModel::Ur5e => {
            let prefix = first.strip_suffix("shoulder_pan_joint").unwrap_or_default();
            format!("{prefix}base")
        }
        // MetaWorld's world frame is the Sawyer's base frame.
        RobotModel::Sawyer => "base".into(),
        // gym-aloha's `vx300s_left` / `vx300s_right` root bodies.
        RobotModel::Vx300s => first
            .split_once('/')
            .map_or_else(|| "base_link".into(), |(p, _)| p.to_string()),
    }
}

fn header(stamp_ns: u64, frame_id: String) -> Header {
    Header {
        stamp: Time::from_ns(stamp_ns),
        frame_id,
    }
}

/// The arm driver's `JointState`.
pub fn joint_state(arm: &Arm, s: &ArmState, stamp_ns: u64) -> JointState {
    JointState {
        header: header(stamp_ns, String::new()),
        name: arm.joint_names.clone(),
        position: s.q.clone(),
        velocity: s.qd.clone(),
        effort: vec![0.0; s.q.len()],
    }
}

/// A `JointState` of the arm's joint positions `q` (rig order), velocities and efforts zero.
pub fn joint_state_of(arm: &Arm, q: &[f64], stamp_ns: u64) -> JointState {
    JointState {
        header: header(stamp_ns, String::new()),
        name: arm.joint_names.clone(),
        position: q.to_vec(),
        velocity: vec![0.0; q.len()],
        effort: vec![0.0; q.len()],
    }
}

/// The gripper driver's `JointState` for an opening of `width_m`.
pub fn gripper_state(g: &Gripper, width_m: f64, stamp_ns: u64) -> JointState {
    let n = g.joint_names.len();
    JointState {
        header: header(stamp_ns, String::new()),
        name: g.joint_names.clone(),
        position: g.model.positions_for_width(width_m, n),
        velocity: vec![0.0; n],
        effort: vec![0.0; n],
    }
}

/// A camera's `Image` around `pixels` (tightly packed rows in the camera's encoding).
pub fn image(cam: &Camera, pixels: Vec<u8>, stamp_ns: u64) -> Image {
    let channels = render::layout(cam.encoding()).map_or(3, |l| l.0) as u32;
    Image {
        header: header(stamp_ns, format!("{}_camera_optical_frame", cam.name)),
        height: cam.height,
        width: cam.width,
        encoding: cam.encoding().to_string(),
        is_bigendian: 0,
        step: cam.width * channels,
        data: pixels,
    }
}

/// What arm `arm`'s command topic carries for `cmd` (CDR), by the rig's command type: a
/// `JointState` of its joint targets, or a `PoseStamped` of its TCP target (joint targets on a
/// pose topic go as their TCP pose, by forward kinematics). `None` when the command holds
/// nothing that topic carries (a bare pose for a joint topic would need inverse kinematics).
pub fn arm_command_cdr(arm: &Arm, cmd: &ArmCommand, stamp_ns: u64) -> Option<Vec<u8>> {
    match (arm.command_type.unwrap_or_default(), &cmd.joints, cmd.pose) {
        (CommandType::JointState, Some(q), _) => Some(joint_state_of(arm, q, stamp_ns).to_cdr()),
        (CommandType::PoseStamped, _, Some(pose)) => {
            Some(pose_command(arm, &pose, stamp_ns).to_cdr())
        }
        (CommandType::PoseStamped, Some(q), None) => {
            let pose = arm.model.base_from_flange(q).ok()? * crate::scene::flange_from_tcp(arm);
            Some(pose_command(arm, &pose, stamp_ns).to_cdr())
        }
        _ => None,
    }
}

/// A TCP target (`base_from_tcp`) as the `PoseStamped` a leader device sends.
pub fn pose_command(arm: &Arm, base_from_tcp: &DMat4, stamp_ns: u64) -> PoseStamped {
    let p = base_from_tcp.w_axis.truncate();
    let mut q = DQuat::from_mat3(&DMat3::from_mat4(*base_from_tcp)).normalize();
    if q.w < 0.0 {
        q = -q;
    }
    PoseStamped {
        header: header(stamp_ns, base_frame_id(arm)),
        pose: Pose {
            position: Point {
                x: p.x,
                y: p.y,
                z: p.z,
            },
            orientation: Quaternion {
                x: q.x,
                y: q.y,
                z: q.z,
                w: q.w,
            },
        },
    }
}

/// A gripper target as a leader gripper's `JointState` (the follower's finger names and units).
pub fn gripper_command(g: &Gripper, width_m: f64, stamp_ns: u64) -> JointState {
    let n = g.joint_names.len();
    JointState {
        header: header(stamp_ns, String::new()),
        name: g.joint_names.clone(),
        position: g.model.positions_for_width(width_m, n),
        velocity: Vec::new(),
        effort: Vec::new(),
    }
}

/// `base_from_tcp` of a pose command; `None` for non-finite values or a zero quaternion.
pub fn read_pose_command(p: &PoseStamped) -> Option<DMat4> {
    let o = p.pose.orientation;
    let q = DQuat::from_xyzw(o.x, o.y, o.z, o.w);
    let pos = DVec3::new(p.pose.position.x, p.pose.position.y, p.pose.position.z);
    if !q.is_finite() || q.length() < 1e-6 || !pos.is_finite() {
        return None;
    }
    Some(DMat4::from_rotation_translation(q.normalize(), pos))
}

/// The opening (m) a gripper command asks for, its joints mapped by name; `None` when one of
/// the gripper's joints is missing or not finite.
pub fn read_gripper_command(g: &Gripper, js: &JointState) -> Option<f64> {
    let positions: Option<Vec<f64>> = g
        .joint_names
        .iter()
        .map(|n| {
            let i = js.name.iter().position(|x| x == n)?;
            js.position.get(i).copied().filter(|v| v.is_finite())
        })
        .collect();
    positions.map(|p| g.model.width_m(&p))
}

/// `base_from_tcp` of a leader arm's joints (mapped by name) through the follower's kinematics.
pub fn read_joint_command(arm: &Arm, flange_from_tcp: &DMat4, js: &JointState) -> Option<DMat4> {
    arm.model
        .base_from_flange(&read_joints(arm, js)?)
        .ok()
        .map(|f| f * *flange_from_tcp)
}

/// The arm's joint positions in a `JointState` (mapped by name, rig order; `None` when one is
/// missing or a value is not finite).
pub fn read_joints(arm: &Arm, js: &JointState) -> Option<Vec<f64>> {
    arm.joint_names
        .iter()
        .map(|n| {
            let i = js.name.iter().position(|x| x == n)?;
            js.position.get(i).copied().filter(|v| v.is_finite())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use scaledp_schema::{Rig, RosMessage};

    use super::*;

    #[test]
    fn commands_round_trip_through_their_messages() {
        let rig = Rig::builtin("bimanual_ur5_3rs").unwrap();
        let arm = &rig.arms[1];
        assert_eq!(base_frame_id(arm), "right_base");
        let franka = Rig::builtin("franka_2zed").unwrap();
        assert_eq!(base_frame_id(&franka.arms[0]), "fr3_link0");
        let t = DMat4::from_translation(DVec3::new(-0.4, 0.1, 0.3))
            * DMat4::from_rotation_x(2.9)
            * DMat4::from_rotation_z(0.7);
        let msg = PoseStamped::from_cdr(&pose_command(arm, &t, 5).to_cdr()).unwrap();
        assert_eq!(msg.header.stamp.as_ns(), 5);
        let back = read_pose_command(&msg).unwrap();
        assert!((back - t).abs_diff_eq(DMat4::ZERO, 1e-12), "{back} vs {t}");
        let g = arm.gripper.as_ref().unwrap();
        let js = JointState::from_cdr(&gripper_command(g, 0.031, 6).to_cdr()).unwrap();
        assert!((read_gripper_command(g, &js).unwrap() - 0.031).abs() < 1e-12);
        let mut wrong = js.clone();
        wrong.name = vec!["other".into()];
        assert_eq!(read_gripper_command(g, &wrong), None);
        let mut bad = msg.clone();
        bad.pose.orientation = Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 0.0,
        };
        assert_eq!(read_pose_command(&bad), None);
    }
}
