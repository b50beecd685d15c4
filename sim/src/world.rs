//! The deterministic core of the simulator: arms that follow Cartesian commands, grippers, and
//! the task's cubes, advanced by [`World::step`] without threads, clocks or randomness of its own
//! (the seed only places the cubes). The live runtime and the offline writer both drive it.
//!
//! Time is kept in integer nanoseconds since the last reset. Each arm's controller ticks at its
//! rig's joint-state rate (`rate_hz`): a tick runs one damped-least-squares step of the
//! [`ik`](crate::ik) controller towards the latest commanded TCP pose (joint velocity and
//! position limits enforced) and one gripper step towards the latest commanded opening.

use std::sync::Arc;

use glam::DMat4;
use scaledp_schema::rig::{GripperModel, Rig};

use crate::ik::{self, IkParams};
use crate::scene::Scene;
use crate::task::{Task, TaskState};

/// What one arm is told to do; `None` fields keep the previous command (a controller holds its
/// last target).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ArmCommand {
    /// The TCP target, `base_from_tcp`, in the arm's base frame.
    pub pose: Option<DMat4>,
    /// Joint targets (rad, the rig's joint order), as a leader arm sends them: what a
    /// joint-commanded simulator (ALOHA) takes; the built-in cell tracks their TCP pose.
    pub joints: Option<Vec<f64>>,
    /// The gripper opening target (m).
    pub gripper_width_m: Option<f64>,
}

/// One arm as measured.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmState {
    /// Joint positions (rad), in the rig's joint order.
    pub q: Vec<f64>,
    /// Joint velocities (rad/s) over the last controller tick.
    pub qd: Vec<f64>,
    /// Gripper opening (m).
    pub gripper_width_m: f64,
    /// `world_from_base` of this arm.
    pub world_from_base: DMat4,
    /// The TCP as measured, `base_from_tcp`.
    pub tcp: DMat4,
    /// The TCP target the controller follows, `base_from_tcp`.
    pub target: DMat4,
    /// The commanded gripper opening (m).
    pub gripper_command_m: f64,
}

/// A snapshot of the whole world.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldState {
    /// Seconds since the last reset.
    pub t_s: f64,
    /// Per arm, in rig order.
    pub arms: Vec<ArmState>,
    /// Cubes, targets and the scorer.
    pub task: TaskState,
}

#[derive(Debug, Clone)]
struct ArmSim {
    q: Vec<f64>,
    qd: Vec<f64>,
    target: DMat4,
    width_m: f64,
    width_command_m: f64,
    max_width_m: f64,
    gripper_speed_mps: f64,
    period_ns: u64,
    next_tick_ns: u64,
}

/// The simulated cell: arms, grippers, cubes.
#[derive(Debug, Clone)]
pub struct World {
    scene: Arc<Scene>,
    arms: Vec<ArmSim>,
    task: Task,
    time_ns: u64,
    params: IkParams,
}

/// Gripper opening speed (m/s): Franka Hand 0.1, Robotiq 2F-85 0.15 (its top speed is 0.15).
fn gripper_speed_mps(model: Option<GripperModel>) -> f64 {
    match model {
        Some(GripperModel::Robotiq2f85) => 0.15,
        _ => 0.1,
    }
}

impl World {
    /// The cell of `rig` reset to `seed`.
    pub fn new(rig: &Rig, seed: u64) -> Self {
        Self::with_scene(Arc::new(Scene::new(rig)), seed)
    }

    /// A world on an existing scene (building a scene solves inverse kinematics for each rest
    /// posture; share one across resets).
    pub fn with_scene(scene: Arc<Scene>, seed: u64) -> Self {
        let mut w = Self {
            arms: Vec::new(),
            task: Task::new(&scene, seed),
            scene,
            time_ns: 0,
            params: IkParams::default(),
        };
        w.reset(seed);
        w
    }

    /// Back to rest: arms at their home posture holding it, grippers open, new cubes and targets
    /// from `seed`, the clock at zero.
    pub fn reset(&mut self, seed: u64) {
        self.task = Task::new(&self.scene, seed);
        self.time_ns = 0;
        self.arms = self
            .scene
            .arms()
            .iter()
            .map(|a| {
                let max_width_m = a
                    .arm
                    .gripper
                    .as_ref()
                    .map_or(0.08, |g| g.model.max_width_m());
                let period_ns = (1e9 / a.arm.rate_hz).round().max(1.0) as u64;
                ArmSim {
                    q: a.home_q.clone(),
                    qd: vec![0.0; a.home_q.len()],
                    target: a.base_from_flange(&a.home_q) * a.flange_from_tcp,
                    width_m: max_width_m,
                    width_command_m: max_width_m,
                    max_width_m,
                    gripper_speed_mps: gripper_speed_mps(a.arm.gripper.as_ref().map(|g| g.model)),
                    period_ns,
                    next_tick_ns: period_ns,
                }
            })
            .collect();
    }

    /// Advances the world by `dt_s` after applying `commands` (one per arm, in rig order; a
    /// shorter slice leaves the remaining arms' commands as they were). Non-finite commands are
    /// ignored. Every controller tick that falls due within the step runs, in time order.
    pub fn step(&mut self, dt_s: f64, commands: &[ArmCommand]) {
        for ((arm, layout), cmd) in self.arms.iter_mut().zip(self.scene.arms()).zip(commands) {
            // Joint targets: the cell's Cartesian controller tracks their TCP pose.
            let from_joints = || {
                let q = cmd.joints.as_ref()?;
                (q.len() == layout.home_q.len())
                    .then(|| layout.base_from_flange(q) * layout.flange_from_tcp)
            };
            if let Some(p) = cmd.pose.or_else(from_joints).filter(|p| p.is_finite()) {
                arm.target = p;
            }
            if let Some(w) = cmd.gripper_width_m.filter(|w| w.is_finite()) {
                arm.width_command_m = w.clamp(0.0, arm.max_width_m);
            }
        }
        let end = self.time_ns + (dt_s.max(0.0) * 1e9).round() as u64;
        loop {
            let next = self
                .arms
                .iter()
                .map(|a| a.next_tick_ns)
                .min()
                .unwrap_or(u64::MAX);
            if next > end {
                break;
            }
            self.task.fall((next - self.time_ns) as f64 * 1e-9);
            self.time_ns = next;
            for i in 0..self.arms.len() {
                if self.arms[i].next_tick_ns == next {
                    self.tick(i);
                }
            }
            self.task.score(self.time_ns);
        }
        self.task.fall((end - self.time_ns) as f64 * 1e-9);
        self.time_ns = end;
        self.task.score(self.time_ns);
    }

    fn tick(&mut self, i: usize) {
        let layout = &self.scene.arms()[i];
        let arm = &mut self.arms[i];
        let dt_s = arm.period_ns as f64 * 1e-9;
        ik::track(
            layout.arm.model,
            &layout.flange_from_tcp,
            &arm.target,
            &layout.home_q,
            &self.params,
            dt_s,
            &mut arm.q,
            &mut arm.qd,
        );
        let fingertips = layout.world_from_fingertips(&arm.q);
        self.task.gripper_tick(
            i,
            &fingertips,
            &mut arm.width_m,
            arm.width_command_m,
            arm.gripper_speed_mps * dt_s,
        );
        arm.next_tick_ns += arm.period_ns;
    }

    /// A snapshot of arms and task.
    pub fn state(&self) -> WorldState {
        WorldState {
            t_s: self.time_s(),
            arms: (0..self.arms.len()).map(|i| self.arm_state(i)).collect(),
            task: self.task_state(),
        }
    }

    /// Arm `i` as measured (panics if there is no arm `i`).
    pub fn arm_state(&self, i: usize) -> ArmState {
        let (a, l) = (&self.arms[i], &self.scene.arms()[i]);
        ArmState {
            q: a.q.clone(),
            qd: a.qd.clone(),
            gripper_width_m: a.width_m,
            world_from_base: l.world_from_base,
            tcp: l.base_from_flange(&a.q) * l.flange_from_tcp,
            target: a.target,
            gripper_command_m: a.width_command_m,
        }
    }

    /// The task's privileged state.
    pub fn task_state(&self) -> TaskState {
        self.task.state(self.time_ns)
    }

    /// The cubes and targets.
    pub fn task(&self) -> &Task {
        &self.task
    }

    /// The fixed geometry.
    pub fn scene(&self) -> &Arc<Scene> {
        &self.scene
    }

    /// Nanoseconds since the last reset.
    pub fn time_ns(&self) -> u64 {
        self.time_ns
    }

    /// Seconds since the last reset.
    pub fn time_s(&self) -> f64 {
        self.time_ns as f64 * 1e-9
    }

    /// The shortest controller period of any arm (ns): the step a live runtime ticks at.
    pub fn tick_ns(&self) -> u64 {
        self.arms
            .iter()
            .map(|a| a.period_ns)
            .min()
            .unwrap_or(1_000_000)
    }
}

#[cfg(test)]
mod tests;
