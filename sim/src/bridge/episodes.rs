//! A bridge's observations and commands as the rig's topics on a Zenoh session (the keys and
//! CDR payloads of zenoh-bridge-ros2dds or rmw_zenoh, stamped on the simulation's clock), and
//! the scripted expert's episodes published through them (what `scaledp collect` records).

use std::sync::atomic::{AtomicBool, Ordering};

use scaledp_recorder::keys::{bridge_key, rmw_key, RmwAttachment};
use scaledp_recorder::now_ns;
use scaledp_schema::{Rig, RosMessage};
use zenoh::pubsub::Publisher;
use zenoh::qos::CongestionControl;
use zenoh::Wait;

use super::{Bridge, Observation};
use crate::world::ArmCommand;
use crate::{messages, Error, KeyStyle, Result};

/// One topic's publisher and its rmw_zenoh sequence.
struct Topic {
    name: String,
    publisher: Publisher<'static>,
    gid: Option<Vec<u8>>,
    seq: i64,
}

impl Topic {
    fn put(&mut self, payload: Vec<u8>) -> Result<()> {
        self.seq += 1;
        let put = self.publisher.put(payload);
        let put = match &self.gid {
            Some(gid) => put.attachment(
                RmwAttachment {
                    sequence_number: self.seq,
                    source_timestamp_ns: now_ns() as i64,
                    source_gid: gid.clone(),
                }
                .to_zbytes(),
            ),
            None => put,
        };
        put.wait().map_err(|e| Error::Zenoh {
            key: self.name.clone(),
            reason: e.to_string(),
        })
    }
}

/// The rig's topics, declared on a session.
pub struct Publishers {
    rig: Rig,
    cameras: Vec<Topic>,
    joints: Vec<Topic>,
    grippers: Vec<Option<Topic>>,
    poses: Vec<Option<Topic>>,
    gripper_commands: Vec<Option<Topic>>,
}

impl Publishers {
    /// Declares every state topic of `rig` and its command topics, keys in `keys` style
    /// (bridge keys under `namespace`).
    pub fn declare(
        session: &zenoh::Session,
        rig: &Rig,
        keys: KeyStyle,
        namespace: &str,
    ) -> Result<Self> {
        let mut n = 0u8;
        let mut topic = |name: &str, message_type: &str| -> Result<Topic> {
            let key = match keys {
                KeyStyle::Bridge => bridge_key(namespace, name),
                KeyStyle::Rmw => rmw_key(0, name, message_type, "TypeHashNotSupported"),
            };
            n = n.wrapping_add(1);
            let publisher = session
                .declare_publisher(key.clone())
                .congestion_control(CongestionControl::Block)
                .wait()
                .map_err(|e| Error::Zenoh {
                    key: key.clone(),
                    reason: e.to_string(),
                })?;
            Ok(Topic {
                name: name.to_string(),
                publisher,
                gid: (keys == KeyStyle::Rmw).then(|| vec![n; 16]),
                seq: 0,
            })
        };
        let js = "sensor_msgs/msg/JointState";
        let cameras = rig
            .cameras
            .iter()
            .map(|c| topic(&c.topic, c.message_type()))
            .collect::<Result<_>>()?;
        let mut joints = Vec::new();
        let (mut grippers, mut poses, mut gripper_commands) = (Vec::new(), Vec::new(), Vec::new());
        for arm in &rig.arms {
            joints.push(topic(&arm.joint_state_topic, js)?);
            grippers.push(match &arm.gripper {
                Some(g) => Some(topic(&g.topic, js)?),
                None => None,
            });
            poses.push(match &arm.command_topic {
                Some(t) => Some(topic(
                    t,
                    arm.command_type.unwrap_or_default().message_type(),
                )?),
                None => None,
            });
            gripper_commands.push(
                match arm.gripper.as_ref().and_then(|g| g.command_topic.as_ref()) {
                    Some(t) => Some(topic(t, js)?),
                    None => None,
                },
            );
        }
        Ok(Publishers {
            rig: rig.clone(),
            cameras,
            joints,
            grippers,
            poses,
            gripper_commands,
        })
    }

    /// Publishes `obs` stamped `stamp_ns`: its images (when rendered), then each arm's joints
    /// and gripper.
    pub fn observation(&mut self, obs: &Observation, stamp_ns: u64) -> Result<()> {
        for ((cam, t), px) in self
            .rig
            .cameras
            .iter()
            .zip(&mut self.cameras)
            .zip(&obs.images)
        {
            t.put(messages::image(cam, px.clone(), stamp_ns).to_cdr())?;
        }
        for (i, (arm, a)) in self.rig.arms.iter().zip(&obs.arms).enumerate() {
            let js = messages::joint_state_of(arm, &a.q, stamp_ns);
            self.joints[i].put(js.to_cdr())?;
            if let (Some(g), Some(t)) = (&arm.gripper, self.grippers[i].as_mut()) {
                let mut m = messages::gripper_state(g, 0.0, stamp_ns);
                m.position = a.gripper_q.clone();
                m.velocity = vec![0.0; a.gripper_q.len()];
                m.effort = vec![0.0; a.gripper_q.len()];
                t.put(m.to_cdr())?;
            }
        }
        Ok(())
    }

    /// Publishes per arm its target (a TCP pose or joint targets, as the arm's command type
    /// says; joint targets on a pose topic go as their TCP pose) and gripper opening, where the
    /// rig has command topics.
    pub fn commands(&mut self, commands: &[ArmCommand], stamp_ns: u64) -> Result<()> {
        for (i, (arm, c)) in self.rig.arms.iter().zip(commands).enumerate() {
            if let (Some(t), Some(m)) = (
                self.poses[i].as_mut(),
                messages::arm_command_cdr(arm, c, stamp_ns),
            ) {
                t.put(m)?;
            }
            let g = arm.gripper.as_ref();
            if let (Some(g), Some(w), Some(t)) =
                (g, c.gripper_width_m, self.gripper_commands[i].as_mut())
            {
                t.put(messages::gripper_command(g, w, stamp_ns).to_cdr())?;
            }
        }
        Ok(())
    }
}

/// How a scripted expert's episode ended.
#[derive(Debug, Clone, PartialEq)]
pub struct ExpertEpisode {
    /// The task succeeded.
    pub success: bool,
    /// Steps taken.
    pub steps: u64,
    /// Simulated time of the first success (s).
    pub time_to_success_s: Option<f64>,
    /// Simulated length (s).
    pub duration_s: f64,
}

/// Runs the expert's episode of `seed` and publishes it: the first observation, then per step
/// the expert's commands (stamped at the step they act on) and the observation they lead to,
/// all stamped `origin_ns` + simulated time. `on_start` runs after the reset and before the
/// first message (start a recording there). The episode ends `tail_steps` after the first
/// success, at the simulator's last step, or when `stop` is set.
pub fn expert_episode(
    bridge: &mut Bridge,
    out: &mut Publishers,
    seed: u64,
    origin_ns: u64,
    tail_steps: u64,
    on_start: &mut dyn FnMut(),
    stop: &AtomicBool,
) -> Result<ExpertEpisode> {
    let dt = bridge.step_ns();
    let first = bridge.reset(seed, true)?;
    on_start();
    out.observation(&first, origin_ns)?;
    let mut success_at = None;
    let mut step = 0u64;
    loop {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        let obs = bridge.expert_step(true)?;
        out.commands(&obs.commands, origin_ns + step * dt)?;
        step = obs.step;
        out.observation(&obs, origin_ns + step * dt)?;
        if obs.success && success_at.is_none() {
            success_at = Some(step);
        }
        let tail_done = success_at.is_some_and(|s| step >= s + tail_steps);
        if tail_done || obs.done {
            break;
        }
    }
    let s = dt as f64 * 1e-9;
    Ok(ExpertEpisode {
        success: success_at.is_some(),
        steps: step,
        time_to_success_s: success_at.map(|k| k as f64 * s),
        duration_s: step as f64 * s,
    })
}
