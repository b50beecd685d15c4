//! The action taken from command topics: an arm with a `command_topic` (`PoseStamped` TCP
//! targets, or a leader arm's joint states through this arm's kinematics) gives the action's
//! pose at each tick, a gripper with one the action's opening, instead of the next tick's state.
//! In joint space a leader arm's joint states are the action's joints as they are; a pose
//! target has no joints without inverse kinematics, so such an arm keeps the next tick's.

use std::path::Path;

use scaledp_schema::rig::Rig;
use scaledp_schema::ActionSpace;

use crate::error::{Error, Result};
use crate::kinematics::ArmKinematics;
use crate::options::ConvertOptions;
use crate::series::{messages_of, CommandPoses, JointSeries};
use crate::source::{RawMessage, Recording};
use scaledp_align::Stream;

/// Arms with a command topic take the action's pose from the latest command at each tick
/// (instead of the next tick's state), its angles put on the state's branch; grippers with a
/// command topic likewise the action's opening. Returns the messages reordered on those topics.
#[allow(clippy::too_many_arguments)]
pub(crate) fn command_actions(
    path: &Path,
    rig: &Rig,
    kin: &[ArmKinematics],
    rec: &Recording,
    ticks_ns: &[u64],
    state_ticks: &[Vec<f32>],
    action: &mut [f32],
    opts: &ConvertOptions,
) -> Result<usize> {
    let space = opts.action_space;
    let dim = space.dim(rig);
    let mut reordered = 0;
    for (a, (arm, k)) in rig.arms.iter().zip(kin).enumerate() {
        let at = space.arm_range(rig, a).start;
        let gripper_at = at + space.arm_dim(arm) - 1;
        // --- gripper command (scaledp-sim, issue 10): a gripper's `command_topic` (a leader
        // gripper's JointState, its joints mapped by name) gives the action's gripper opening:
        // the latest command at each tick.
        if let Some((g, topic)) = arm
            .gripper
            .as_ref()
            .and_then(|g| Some((g, g.command_topic.as_ref()?)))
        {
            let msgs = messages_of(rec, topic, opts);
            let rate = rig.control_rate_hz;
            let cmd = JointSeries::read(path, &msgs, topic, &g.joint_names, rate, opts)?;
            if cmd.positions.is_empty() {
                return Err(Error::Rejected {
                    path: path.into(),
                    reason: format!(
                        "gripper command topic {topic} of arm '{}' has no messages",
                        arm.name
                    ),
                });
            }
            reordered += cmd.reordered;
            for (t, tick) in ticks_ns.iter().enumerate() {
                let i = cmd.stream.latest_at(*tick).unwrap_or(0);
                action[t * dim + gripper_at] = g.model.width_m(&cmd.positions[i]) as f32;
            }
        }
        // --- end gripper command
        let Some(topic) = &arm.command_topic else {
            continue;
        };
        let msgs = messages_of(rec, topic, opts);
        if space == ActionSpace::Joints {
            reordered += joint_commands(path, rig, a, &msgs, ticks_ns, action, opts)?;
            continue;
        }
        let command = CommandPoses::read(path, &msgs, arm, k, opts)?;
        if command.stamps_ns.is_empty() {
            return Err(Error::Rejected {
                path: path.into(),
                reason: format!(
                    "command topic {topic} of arm '{}' has no messages",
                    arm.name
                ),
            });
        }
        reordered += command.reordered;
        let stream = Stream::new(topic, command.stamps_ns, None);
        let chosen: Vec<usize> = ticks_ns
            .iter()
            .map(|tick| stream.latest_at(*tick).unwrap_or(0))
            .collect();
        // Put the command's angles on the state's branch (within π of it at the first tick),
        // so action − state never carries a spurious full turn.
        let mut turn = [0.0; 6];
        if let Some(&first) = chosen.first() {
            for (d, shift) in turn.iter_mut().enumerate().skip(3) {
                let gap = f64::from(state_ticks[0][at + d]) - command.poses[first][d];
                *shift = std::f64::consts::TAU * (gap / std::f64::consts::TAU).round();
            }
        }
        for (t, &i) in chosen.iter().enumerate() {
            for (d, v) in command.poses[i].iter().enumerate() {
                action[t * dim + at + d] = (*v + turn[d]) as f32;
            }
        }
    }
    Ok(reordered)
}

/// Joint space: the latest leader joints at each tick become arm `a`'s action joints (a
/// `PoseStamped` command topic leaves the next tick's joints). Returns the reordered count.
fn joint_commands(
    path: &Path,
    rig: &Rig,
    a: usize,
    msgs: &[&RawMessage],
    ticks_ns: &[u64],
    action: &mut [f32],
    opts: &ConvertOptions,
) -> Result<usize> {
    let arm = &rig.arms[a];
    let Some(first) = msgs.first() else {
        return Err(Error::Rejected {
            path: path.into(),
            reason: format!(
                "command topic {} of arm '{}' has no messages",
                arm.command_topic.as_deref().unwrap_or_default(),
                arm.name
            ),
        });
    };
    if !first.message_type.ends_with("/JointState") {
        return Ok(0);
    }
    let (space, dim) = (ActionSpace::Joints, ActionSpace::Joints.dim(rig));
    let at = space.arm_range(rig, a).start;
    let topic = first.topic.clone();
    let cmd = JointSeries::read(path, msgs, &topic, &arm.joint_names, arm.rate_hz, opts)?;
    for (t, tick) in ticks_ns.iter().enumerate() {
        let i = cmd.stream.latest_at(*tick).unwrap_or(0);
        for (d, v) in cmd.positions[i].iter().enumerate() {
            action[t * dim + at + d] = *v as f32;
        }
    }
    Ok(cmd.reordered)
}
