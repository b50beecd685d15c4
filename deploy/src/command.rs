//! One arm's action turned into what its command topic takes, within the safety limits.
//!
//! The checkpoint's action space and the arm's command type need not agree: a TCP action for an
//! arm that takes joint targets (a leader arm's `JointState`, as ALOHA's) goes through inverse
//! kinematics from the last joints; a joint action for an arm that takes TCP targets goes as
//! its TCP pose by forward kinematics. Both are clamped in the space they were predicted in,
//! then the TCP they reach is held to the workspace box and the per-tick step.

use glam::DMat4;
use scaledp_converter::live::ArmKinematics;
use scaledp_schema::kinematics::rotation_from_rpy;
use scaledp_schema::rig::{Arm, CommandType};
use scaledp_schema::ActionSpace;

use crate::safety::{clamp_pose, Clamped, Limits, Workspace};

/// An arm's command before the gripper: the TCP target and, for an arm taking joint targets,
/// the joints.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Target {
    pub base_from_tcp: DMat4,
    pub joints: Option<Vec<f64>>,
}

/// Where the arm's last command left it (else where it was measured): its TCP and joints.
pub(crate) struct Previous<'a> {
    pub tcp: DMat4,
    pub joints: &'a [f64],
}

/// Inverse-kinematics iterations per command (a TCP action for a joint-commanded arm): the
/// target is one tick from the last command, so a few damped steps reach it.
const IK_ITERATIONS: usize = 20;

/// The target of `v` (the arm's slice of the action, gripper excluded) in `space`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn arm_target(
    arm: &Arm,
    kin: &ArmKinematics,
    space: ActionSpace,
    v: &[f64],
    previous: &Previous<'_>,
    ws: &Workspace,
    limits: &Limits,
    clamped: &mut Clamped,
) -> Target {
    let takes_joints = arm.command_type.unwrap_or_default() == CommandType::JointState;
    match space {
        ActionSpace::Tcp => {
            let target = DMat4::from_translation(glam::DVec3::new(v[0], v[1], v[2]))
                * DMat4::from_mat3(rotation_from_rpy([v[3], v[4], v[5]]));
            let pose = clamp_pose(target, previous.tcp, ws, limits, clamped);
            let joints = takes_joints.then(|| {
                let tcp = scaledp_sim::scene::flange_from_tcp(arm);
                scaledp_sim::ik::solve(arm.model, &tcp, &pose, previous.joints, IK_ITERATIONS).0
            });
            Target {
                base_from_tcp: pose,
                joints,
            }
        }
        ActionSpace::Joints => {
            let q = clamp_joints(arm, kin, v, previous, ws, limits, clamped);
            let base_from_tcp = kin.base_from_tcp(&q).unwrap_or(previous.tcp);
            Target {
                base_from_tcp,
                joints: takes_joints.then_some(q),
            }
        }
    }
}

/// Joint targets `v` within the arm's joint limits and `max_step_rad` of the previous joints
/// per joint, then shortened (halving the step from the previous joints, at most 12 times)
/// until the TCP they reach lies in `ws` and within `max_step_m` / `max_step_rad` of the
/// previous TCP.
fn clamp_joints(
    arm: &Arm,
    kin: &ArmKinematics,
    v: &[f64],
    previous: &Previous<'_>,
    ws: &Workspace,
    limits: &Limits,
    clamped: &mut Clamped,
) -> Vec<f64> {
    let bounds = arm.model.joint_limits();
    let prev = previous.joints;
    let mut q: Vec<f64> = v
        .iter()
        .enumerate()
        .map(|(k, &x)| {
            let (lo, hi) = bounds.get(k).copied().unwrap_or((f64::MIN, f64::MAX));
            let boxed = x.clamp(lo, hi);
            clamped.workspace |= boxed != x;
            let p = prev.get(k).copied().unwrap_or(boxed);
            let stepped = boxed.clamp(p - limits.max_step_rad, p + limits.max_step_rad);
            clamped.step |= stepped != boxed;
            stepped
        })
        .collect();
    let fits = |q: &[f64]| {
        let Ok(t) = kin.base_from_tcp(q) else {
            return false;
        };
        let mut c = Clamped::default();
        let held = clamp_pose(t, previous.tcp, ws, limits, &mut c);
        !c.any() || held.abs_diff_eq(t, 1e-9)
    };
    if prev.len() == q.len() && !fits(&q) {
        clamped.workspace = true;
        let step: Vec<f64> = q.iter().zip(prev).map(|(a, b)| a - b).collect();
        let mut scale = 1.0;
        for _ in 0..12 {
            scale *= 0.5;
            q = prev.iter().zip(&step).map(|(p, d)| p + d * scale).collect();
            if fits(&q) {
                return q;
            }
        }
        return prev.to_vec();
    }
    q
}

#[cfg(test)]
mod tests {
    use scaledp_schema::Rig;

    use super::*;

    fn setup() -> (Rig, ArmKinematics, Workspace, Limits) {
        let rig = Rig::builtin("aloha/transfer-cube").unwrap();
        let kin = ArmKinematics::new(&rig.arms[0]).unwrap();
        let ws = Workspace::for_rig(&rig)[0];
        let limits = Limits {
            workspace: vec![ws],
            max_step_m: 0.05,
            max_step_rad: 0.25,
        };
        (rig, kin, ws, limits)
    }

    const HOME: [f64; 6] = [0.0, -0.96, 1.16, 0.0, -0.3, 0.0];

    #[test]
    fn joint_actions_stay_within_a_step_the_limits_and_the_box() {
        let (rig, kin, ws, limits) = setup();
        let arm = &rig.arms[0];
        let prev = Previous {
            tcp: kin.base_from_tcp(&HOME).unwrap(),
            joints: &HOME,
        };
        // A small move passes as it is, sent as joints (the arm takes a leader's JointState).
        let near: Vec<f64> = HOME.iter().map(|q| q + 0.01).collect();
        let mut c = Clamped::default();
        let t = arm_target(
            arm,
            &kin,
            ActionSpace::Joints,
            &near,
            &prev,
            &ws,
            &limits,
            &mut c,
        );
        assert!(!c.any(), "{c:?}");
        assert_eq!(t.joints.as_deref(), Some(near.as_slice()));
        assert!(t
            .base_from_tcp
            .abs_diff_eq(kin.base_from_tcp(&near).unwrap(), 1e-12));
        // A wild one is cut to a step per joint, and its TCP kept in the box.
        let wild = [3.0, 2.0, -2.0, 3.0, 2.0, 3.0];
        let mut c = Clamped::default();
        let t = arm_target(
            arm,
            &kin,
            ActionSpace::Joints,
            &wild,
            &prev,
            &ws,
            &limits,
            &mut c,
        );
        assert!(c.step);
        let q = t.joints.unwrap();
        for (a, b) in q.iter().zip(HOME) {
            assert!((a - b).abs() <= 0.25 + 1e-12, "{q:?}");
        }
        assert!(ws.contains(t.base_from_tcp.w_axis.truncate()));
        let moved = (t.base_from_tcp.w_axis - prev.tcp.w_axis)
            .truncate()
            .length();
        assert!(moved <= 0.05 + 1e-9, "{moved} m in one tick");
    }

    #[test]
    fn tcp_actions_reach_joint_commanded_arms_through_ik() {
        let (rig, kin, ws, limits) = setup();
        let arm = &rig.arms[0];
        let start = kin.base_from_tcp(&HOME).unwrap();
        let prev = Previous {
            tcp: start,
            joints: &HOME,
        };
        let goal = DMat4::from_translation(glam::DVec3::new(0.02, -0.01, 0.01)) * start;
        let pose = scaledp_schema::kinematics::pose6_from_transform(goal);
        let mut c = Clamped::default();
        let t = arm_target(
            arm,
            &kin,
            ActionSpace::Tcp,
            &pose,
            &prev,
            &ws,
            &limits,
            &mut c,
        );
        assert!(!c.any(), "{c:?}");
        let reached = kin.base_from_tcp(&t.joints.unwrap()).unwrap();
        let gap = (reached.w_axis - goal.w_axis).truncate().length();
        assert!(gap < 1e-4, "IK lands {gap} m from the target");
    }
}
