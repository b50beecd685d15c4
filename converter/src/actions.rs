//! The action taken from command topics: an arm with a `command_topic` (`PoseStamped` TCP
//! targets, or a leader arm's joint states through this arm's kinematics) gives the action's
//! pose at each tick, a gripper with one the action's opening, instead of the next tick's state.

use std::path::Path;

use scaledp_schema::rig::Rig;

use crate::align::Stream;
use crate::error::{Error, Result};
use crate::kinematics::ArmKinematics;
use crate::options::ConvertOptions;
use crate::series::{messages_of, CommandPoses, JointSeries};
use crate::source::Recording;

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
    let dim = 7 * rig.arms.len();
    let mut reordered = 0;
    for (a, (arm, k)) in rig.arms.iter().zip(kin).enumerate() {
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
                action[t * dim + a * 7 + 6] = g.model.width_m(&cmd.positions[i]) as f32;
            }
        }
        // --- end gripper command
        let Some(topic) = &arm.command_topic else {
            continue;
        };
        let msgs = messages_of(rec, topic, opts);
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
                let gap = f64::from(state_ticks[0][a * 7 + d]) - command.poses[first][d];
                *shift = std::f64::consts::TAU * (gap / std::f64::consts::TAU).round();
            }
        }
        for (t, &i) in chosen.iter().enumerate() {
            for (d, v) in command.poses[i].iter().enumerate() {
                action[t * dim + a * 7 + d] = (*v + turn[d]) as f32;
            }
        }
    }
    Ok(reordered)
}
