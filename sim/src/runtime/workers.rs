//! The threads behind a running simulation: the state they share, the command subscribers'
//! decoding, the world's real-time loop and the scripted operator's loop.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use scaledp_recorder::now_ns;
use scaledp_schema::msg::{JointState, PoseStamped};
use scaledp_schema::rig::{CommandType, Rig};
use scaledp_schema::RosMessage;
use serde::Serialize;
use zenoh::sample::Sample;
use zenoh::Wait;

use crate::messages;
use crate::operator::{ScriptedOperator, LEADER_RATE_HZ};
use crate::scene::Scene;
use crate::task::TaskState;
use crate::world::{ArmCommand, ArmState, World, WorldState};

/// Called with (topic, payload) for every message just before it is published.
pub type PublishHook = Arc<dyn Fn(&str, &[u8]) + Send + Sync>;

/// The operator and when it is due to begin.
pub(crate) struct OperatorSlot {
    pub operator: ScriptedOperator,
    pub begin_at: Option<Instant>,
}

/// What every thread of a running simulation shares.
pub(crate) struct Shared {
    pub rig: Rig,
    pub scene: Arc<Scene>,
    pub stop: AtomicBool,
    pub world: Mutex<World>,
    /// Lock order: `operator` before `world`.
    pub operator: Mutex<Option<OperatorSlot>>,
    pub pending: Mutex<Vec<ArmCommand>>,
    pub reset_request: Mutex<Option<Option<u64>>>,
    pub reset_wall_ns: AtomicU64,
}

pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Shared {
    pub(crate) fn state(&self) -> WorldState {
        lock(&self.world).state()
    }

    pub(crate) fn arm_state(&self, i: usize) -> ArmState {
        lock(&self.world).arm_state(i)
    }

    pub(crate) fn reset(&self, seed: u64) {
        let mut op = lock(&self.operator);
        if let Some(slot) = op.as_mut() {
            *slot = OperatorSlot {
                operator: ScriptedOperator::new(&self.scene, seed),
                begin_at: None,
            };
        }
        lock(&self.world).reset(seed);
        lock(&self.pending)
            .iter_mut()
            .for_each(|c| *c = ArmCommand::default());
        self.reset_wall_ns.store(now_ns(), Ordering::Relaxed);
        tracing::debug!(seed, "reset");
    }

    fn push_command(&self, arm: usize, cmd: ArmCommand) {
        if let Some(p) = lock(&self.pending).get_mut(arm) {
            if cmd.pose.is_some() || cmd.joints.is_some() {
                p.pose = cmd.pose;
                p.joints = cmd.joints;
            }
            p.gripper_width_m = cmd.gripper_width_m.or(p.gripper_width_m);
        }
    }

    fn operator_status(&self) -> Option<&'static str> {
        lock(&self.operator).as_ref().map(|s| {
            if s.operator.done() {
                "done"
            } else if s.operator.started() {
                "running"
            } else {
                "waiting"
            }
        })
    }
}

/// Decodes a command sample of arm `arm` into the pending commands.
pub(crate) fn on_command(shared: &Shared, arm: usize, gripper: bool, s: &Sample) {
    let bytes = s.payload().to_bytes();
    let Some(a) = shared.rig.arms.get(arm) else {
        return;
    };
    let cmd = if gripper {
        let (Ok(js), Some(g)) = (JointState::from_cdr(&bytes), a.gripper.as_ref()) else {
            tracing::warn!("{}: not a gripper JointState", s.key_expr());
            return;
        };
        ArmCommand {
            gripper_width_m: messages::read_gripper_command(g, &js),
            ..ArmCommand::default()
        }
    } else {
        let stamp_ns = scaledp_schema::msg::header_stamp(&bytes).map_or(0, |t| t.as_ns());
        if stamp_ns > 0 && stamp_ns < shared.reset_wall_ns.load(Ordering::Relaxed) {
            return;
        }
        let pose = match a.command_type.unwrap_or_default() {
            CommandType::PoseStamped => PoseStamped::from_cdr(&bytes)
                .ok()
                .and_then(|p| messages::read_pose_command(&p)),
            CommandType::JointState => JointState::from_cdr(&bytes).ok().and_then(|js| {
                messages::read_joint_command(a, &shared.scene.arms()[arm].flange_from_tcp, &js)
            }),
        };
        if pose.is_none() {
            tracing::warn!("{}: an unreadable pose command", s.key_expr());
        }
        ArmCommand {
            pose,
            ..ArmCommand::default()
        }
    };
    shared.push_command(arm, cmd);
}

/// Steps the world at the fastest controller rate, applies resets, publishes the task's state.
pub(crate) fn world_loop(shared: &Shared, status: &zenoh::pubsub::Publisher<'static>) {
    let tick_ns = lock(&shared.world).tick_ns();
    let n_arms = shared.rig.arms.len();
    let tick = Duration::from_nanos(tick_ns);
    let mut next = Instant::now();
    let mut next_status = Instant::now();
    while !shared.stop.load(Ordering::Relaxed) {
        next += tick;
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        } else if now - next > Duration::from_millis(200) {
            tracing::debug!("the world fell {:?} behind real time", now - next);
            next = now;
        }
        // (Taken first: a guard in an `if let` scrutinee would live through the block.)
        let request = lock(&shared.reset_request).take();
        if let Some(request) = request {
            let seed = request.unwrap_or_else(|| lock(&shared.world).task().seed() + 1);
            shared.reset(seed);
            if let Some(slot) = lock(&shared.operator).as_mut() {
                slot.begin_at = Some(Instant::now() + Duration::from_millis(500));
            }
        }
        let cmds = std::mem::replace(
            &mut *lock(&shared.pending),
            vec![ArmCommand::default(); n_arms],
        );
        lock(&shared.world).step(tick_ns as f64 * 1e-9, &cmds);
        if Instant::now() >= next_status {
            next_status += Duration::from_millis(100);
            let task = lock(&shared.world).task_state();
            #[derive(Serialize)]
            struct Status<'a> {
                #[serde(flatten)]
                task: &'a TaskState,
                operator: Option<&'static str>,
            }
            let operator = shared.operator_status();
            if let Ok(json) = serde_json::to_vec(&Status {
                task: &task,
                operator,
            }) {
                let _ = status.put(json).wait();
            }
        }
    }
}

pub(crate) type CommandPublisher = Option<(String, zenoh::pubsub::Publisher<'static>)>;

/// The scripted operator at the leader rate: reads the world, publishes its commands.
pub(crate) fn operator_loop(
    shared: &Shared,
    publishers: &[(CommandPublisher, CommandPublisher)],
    hook: Option<&PublishHook>,
    mut autoplay: Option<u64>,
) {
    let period = Duration::from_secs_f64(1.0 / LEADER_RATE_HZ);
    let mut next = Instant::now();
    let mut finished_at: Option<Instant> = None;
    if autoplay.is_some() {
        if let Some(slot) = lock(&shared.operator).as_mut() {
            slot.begin_at = Some(Instant::now() + Duration::from_millis(500));
        }
    }
    while !shared.stop.load(Ordering::Relaxed) {
        next += period;
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        } else if now - next > Duration::from_millis(200) {
            next = now;
        }
        let cmds = {
            let mut slot = lock(&shared.operator);
            let Some(slot) = slot.as_mut() else { return };
            let state = shared.state();
            if slot.begin_at.is_some_and(|at| Instant::now() >= at) {
                slot.begin_at = None;
                slot.operator.begin(state.t_s);
            }
            if let Some(seed) = autoplay.as_mut() {
                let over = slot.operator.done() || (slot.operator.started() && state.t_s > 40.0);
                match (over, finished_at) {
                    (true, None) => finished_at = Some(Instant::now()),
                    (true, Some(at)) if at.elapsed() > Duration::from_secs(1) => {
                        *seed += 1;
                        finished_at = None;
                        let s = *seed;
                        *lock(&shared.reset_request) = Some(Some(s));
                        continue;
                    }
                    _ => {}
                }
            }
            slot.operator.command(state.t_s, &shared.scene, &state)
        };
        let stamp = now_ns();
        for (a, cmd) in cmds.into_iter().enumerate() {
            let arm = &shared.rig.arms[a];
            let (pose_pub, grip_pub) = &publishers[a];
            let mut local = ArmCommand::default();
            match (pose_pub, cmd.pose) {
                (Some((topic, p)), Some(pose)) => {
                    let bytes = messages::pose_command(arm, &pose, stamp).to_cdr();
                    if let Some(h) = hook {
                        h(topic, &bytes);
                    }
                    let _ = p.put(bytes).wait();
                }
                (None, pose) => local.pose = pose,
                _ => {}
            }
            match (grip_pub, cmd.gripper_width_m, &arm.gripper) {
                (Some((topic, p)), Some(w), Some(g)) => {
                    let bytes = messages::gripper_command(g, w, stamp).to_cdr();
                    if let Some(h) = hook {
                        h(topic, &bytes);
                    }
                    let _ = p.put(bytes).wait();
                }
                (None, w, _) => local.gripper_width_m = w,
                _ => {}
            }
            if local != ArmCommand::default() {
                shared.push_command(a, local);
            }
        }
    }
}
