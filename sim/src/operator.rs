//! The scripted expert, as a teleoperator: it moves a leader device, and what leaves it are the
//! commands a leader publishes — the TCP pose (`geometry_msgs/PoseStamped` in the arm's base
//! frame) and the gripper opening — at [`LEADER_RATE_HZ`]. It looks at the scene the way a
//! person at the table does (it reads the task's privileged state: where the cube and the
//! target are, whether the cube is in the fingers) but acts only through those commands.
//!
//! Every episode follows one strategy: a reaction delay; approach above the cube; descend;
//! close; wait for the grasp; lift 12 cm; carry above the target; lower the cube to 6 mm above
//! the table; open; retreat; return home. A missed grasp is retried (twice at most). Each move
//! is a minimum-jerk profile whose duration grows with its length; the seed varies the overall
//! speed (±15 %), each move's duration (±10 %) and each reaction delay, and adds a smooth
//! low-frequency wobble (three sines per axis, ≈3 mm and ≈0.02 rad) plus sensor jitter
//! (≈0.3 mm) to every sample. An episode takes 9–12 s.

use std::collections::VecDeque;

use glam::{DMat3, DMat4, DVec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::scene::{Scene, CUBE_HALF_M};
use crate::world::{ArmCommand, WorldState};

/// How often a leader device reports (Hz).
pub const LEADER_RATE_HZ: f64 = 100.0;

/// Where a move goes, decided from what the operator sees when the move starts.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Goal {
    PreGrasp,
    Grasp,
    Lift,
    AboveTarget,
    Place,
    Retreat,
    Home,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Step {
    Wait(f64),
    Move(Goal),
    AwaitReach,
    Close,
    AwaitGrasp,
    Open,
    AwaitRelease,
}

/// A sum of three sines.
#[derive(Debug, Clone)]
struct Wobble([(f64, f64, f64); 3]);

impl Wobble {
    fn new(rng: &mut ChaCha8Rng, amplitude: f64) -> Self {
        let mut w = [(0.0, 0.0, 0.0); 3];
        for (k, (base_amp, base_hz)) in [(0.5, 0.25), (0.3, 0.6), (0.2, 1.3)].iter().enumerate() {
            w[k] = (
                amplitude * base_amp * rng.random_range(0.7..1.3),
                base_hz * rng.random_range(0.8..1.25),
                rng.random_range(0.0..std::f64::consts::TAU),
            );
        }
        Self(w)
    }
    fn at(&self, t: f64) -> f64 {
        self.0
            .iter()
            .map(|(a, f, p)| a * (std::f64::consts::TAU * f * t + p).sin())
            .sum()
    }
}

#[derive(Debug, Clone)]
struct ArmOperator {
    arm: usize,
    steps: VecDeque<Step>,
    step_started_s: f64,
    /// The current move: from, to, start, duration.
    from: DVec3,
    to: DVec3,
    move_start_s: f64,
    move_s: f64,
    /// The gripper ramp: from, to, start, duration.
    grip: (f64, f64, f64, f64),
    /// Cube centre minus fingertips (world), measured when the carry starts.
    carry_offset: DVec3,
    wobble: [Wobble; 6],
    speed: f64,
    retries: u32,
    open_m: f64,
}

/// Minimum-jerk blend 0 → 1 (zero velocity and acceleration at both ends).
fn min_jerk(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)
}

/// Where the fingertips grasp a cube centred at `cube`: 8 mm below its centre.
fn grasp_point(cube: DVec3) -> DVec3 {
    cube - DVec3::Z * 0.008
}

impl ArmOperator {
    fn nominal(&self, t: f64) -> DVec3 {
        let s = min_jerk((t - self.move_start_s) / self.move_s.max(1e-9));
        self.from + (self.to - self.from) * s
    }

    fn gripper(&self, t: f64) -> f64 {
        let (a, b, t0, d) = self.grip;
        a + (b - a) * ((t - t0) / d.max(1e-9)).clamp(0.0, 1.0)
    }

    /// Starts `step` at `t`: fixes a move's goal and duration, or a gripper ramp.
    fn start(
        &mut self,
        step: Step,
        t: f64,
        scene: &Scene,
        state: &WorldState,
        rng: &mut ChaCha8Rng,
    ) {
        self.step_started_s = t;
        let cube = &state.task.cubes[self.arm];
        let cube_at = DVec3::from_array(cube.position_m);
        let target = DVec3::from_array(cube.target_m);
        let here = self.nominal(t);
        let (goal, careful) = match step {
            Step::Move(g) => {
                let goal = match g {
                    Goal::PreGrasp => grasp_point(cube_at) + DVec3::Z * 0.10,
                    Goal::Grasp => grasp_point(cube_at),
                    Goal::Lift => here + DVec3::Z * 0.12,
                    Goal::AboveTarget => {
                        self.carry_offset = cube_at - self.fingertips(scene, state);
                        (target - self.carry_offset).with_z(here.z)
                    }
                    Goal::Place => {
                        let p = target - self.carry_offset;
                        p.with_z(CUBE_HALF_M + 0.006 - self.carry_offset.z)
                    }
                    Goal::Retreat => here + DVec3::Z * 0.10,
                    Goal::Home => scene.arms()[self.arm].home_fingertips().w_axis.truncate(),
                };
                let careful = matches!(g, Goal::Grasp | Goal::Lift | Goal::Place | Goal::Retreat);
                (goal, careful)
            }
            Step::Close => {
                self.grip = (self.gripper(t), 0.0, t, rng.random_range(0.2..0.35));
                return;
            }
            Step::Open => {
                self.grip = (self.gripper(t), self.open_m, t, rng.random_range(0.15..0.3));
                return;
            }
            _ => return,
        };
        let dist = (goal - here).length();
        let base = if careful {
            0.6 + 5.0 * dist
        } else {
            0.5 + 3.2 * dist
        };
        self.from = here;
        self.to = goal;
        self.move_start_s = t;
        self.move_s = base * self.speed * rng.random_range(0.9..1.1);
    }

    fn fingertips(&self, scene: &Scene, state: &WorldState) -> DVec3 {
        scene.arms()[self.arm]
            .world_from_fingertips(&state.arms[self.arm].q)
            .w_axis
            .truncate()
    }

    /// Whether `step` (started at `step_started_s`) is over at `t`.
    fn progress(&self, step: Step, t: f64, scene: &Scene, state: &WorldState) -> Progress {
        let elapsed = t - self.step_started_s;
        let held = state.task.cubes[self.arm].held_by == Some(self.arm);
        let over = match step {
            Step::Wait(s) => elapsed >= s,
            Step::Move(_) => elapsed >= self.move_s,
            Step::AwaitReach => {
                (self.fingertips(scene, state) - self.to).length() < 0.005 || elapsed > 1.0
            }
            Step::Close | Step::Open => elapsed >= self.grip.3,
            Step::AwaitGrasp if !held && elapsed > 1.2 => return Progress::Missed,
            Step::AwaitGrasp => held,
            Step::AwaitRelease => !held || elapsed > 1.0,
        };
        if over {
            Progress::Over
        } else {
            Progress::Running
        }
    }
}

enum Progress {
    Running,
    Over,
    /// The gripper closed without the cube.
    Missed,
}

/// After a missed grasp: open, back up, look again.
const RETRY: [Step; 7] = [
    Step::Open,
    Step::Wait(0.3),
    Step::Move(Goal::PreGrasp),
    Step::Move(Goal::Grasp),
    Step::AwaitReach,
    Step::Close,
    Step::AwaitGrasp,
];
/// After the last missed grasp: give up and go home.
const GIVE_UP: [Step; 3] = [
    Step::Open,
    Step::Move(Goal::Retreat),
    Step::Move(Goal::Home),
];

/// The scripted teleoperator of every arm of a rig, for one episode.
#[derive(Debug, Clone)]
pub struct ScriptedOperator {
    arms: Vec<ArmOperator>,
    rng: ChaCha8Rng,
    started: bool,
}

impl ScriptedOperator {
    /// The operator of episode `seed` (its own random stream: the same seed, the same hands).
    pub fn new(scene: &Scene, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x0BE7_A70A_0000_0001);
        let speed = rng.random_range(0.85..1.15);
        let arms = scene
            .arms()
            .iter()
            .enumerate()
            .map(|(i, a)| {
                let home = a.home_fingertips().w_axis.truncate();
                let open_m = a
                    .arm
                    .gripper
                    .as_ref()
                    .map_or(0.08, |g| g.model.max_width_m());
                let mut steps: VecDeque<Step> = VecDeque::new();
                steps.push_back(Step::Wait(rng.random_range(0.2..0.5)));
                steps.extend([
                    Step::Move(Goal::PreGrasp),
                    Step::Move(Goal::Grasp),
                    Step::AwaitReach,
                    Step::Close,
                    Step::AwaitGrasp,
                    Step::Wait(rng.random_range(0.15..0.4)),
                    Step::Move(Goal::Lift),
                    Step::Move(Goal::AboveTarget),
                    Step::Move(Goal::Place),
                    Step::AwaitReach,
                    Step::Wait(rng.random_range(0.05..0.2)),
                    Step::Open,
                    Step::AwaitRelease,
                    Step::Wait(rng.random_range(0.1..0.3)),
                    Step::Move(Goal::Retreat),
                    Step::Move(Goal::Home),
                    Step::Wait(0.3),
                ]);
                ArmOperator {
                    arm: i,
                    steps,
                    step_started_s: 0.0,
                    from: home,
                    to: home,
                    move_start_s: 0.0,
                    move_s: 0.0,
                    grip: (open_m, open_m, 0.0, 0.0),
                    carry_offset: DVec3::ZERO,
                    wobble: [0.003, 0.003, 0.003, 0.02, 0.02, 0.02]
                        .map(|a| Wobble::new(&mut rng, a)),
                    speed,
                    retries: 0,
                    open_m,
                }
            })
            .collect();
        Self {
            arms,
            rng,
            started: false,
        }
    }

    /// Starts the demonstration at `t_s` (world time); until then the operator holds the
    /// leader still at rest (its hand still wobbles).
    pub fn begin(&mut self, t_s: f64) {
        if !self.started {
            self.started = true;
            for a in &mut self.arms {
                a.step_started_s = t_s;
                a.move_start_s = t_s;
            }
        }
    }

    /// True once started.
    pub fn started(&self) -> bool {
        self.started
    }

    /// True when every arm has finished its demonstration and is back home.
    pub fn done(&self) -> bool {
        self.started && self.arms.iter().all(|a| a.steps.is_empty())
    }

    /// The leader's sample at world time `t_s`, given what the operator sees (`state`): one
    /// command per arm (both fields set).
    pub fn command(&mut self, t_s: f64, scene: &Scene, state: &WorldState) -> Vec<ArmCommand> {
        let mut out = Vec::with_capacity(self.arms.len());
        for a in &mut self.arms {
            if self.started {
                while let Some(&step) = a.steps.front() {
                    match a.progress(step, t_s, scene, state) {
                        Progress::Running => break,
                        Progress::Over => {
                            a.steps.pop_front();
                        }
                        Progress::Missed => {
                            a.steps.pop_front();
                            a.retries += 1;
                            let then: &[Step] = if a.retries <= 2 { &RETRY } else { &GIVE_UP };
                            if a.retries > 2 {
                                a.steps.clear();
                            }
                            for s in then.iter().rev() {
                                a.steps.push_front(*s);
                            }
                        }
                    }
                    if let Some(&next) = a.steps.front() {
                        a.start(next, t_s, scene, state, &mut self.rng);
                    }
                }
            }
            let layout = &scene.arms()[a.arm];
            let jitter = |rng: &mut ChaCha8Rng, s: f64| {
                (rng.random_range(-1.0..1.0) + rng.random_range(-1.0..1.0)) * s
            };
            let w = |k: usize| a.wobble[k].at(t_s);
            let p = a.nominal(t_s)
                + DVec3::new(w(0), w(1), w(2))
                + DVec3::new(
                    jitter(&mut self.rng, 0.0002),
                    jitter(&mut self.rng, 0.0002),
                    jitter(&mut self.rng, 0.0002),
                );
            let tilt = DVec3::new(
                w(3) + jitter(&mut self.rng, 0.001),
                w(4) + jitter(&mut self.rng, 0.001),
                w(5) + jitter(&mut self.rng, 0.001),
            );
            let r = DMat3::from_axis_angle(tilt.normalize_or(DVec3::X), tilt.length())
                * layout.grasp_rotation;
            let fingertips = DMat4::from_translation(p) * DMat4::from_mat3(r);
            let tcp = layout.world_from_base.inverse() * fingertips * layout.fingertips_from_tcp();
            out.push(ArmCommand {
                pose: Some(tcp),
                joints: None,
                gripper_width_m: Some(a.gripper(t_s)),
            });
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use scaledp_schema::Rig;

    use super::*;
    use crate::headless::run_episode;

    #[test]
    fn the_operator_succeeds_on_every_shipped_rig_and_model_in_eight_to_thirteen_seconds() {
        let mut rigs: Vec<Rig> = Rig::builtin_names().filter_map(Rig::builtin).collect();
        // The same cells with the other models of each family.
        let mut panda = Rig::builtin("franka_sim").unwrap();
        panda.arms[0].model = scaledp_schema::RobotModel::Panda;
        let mut ur5e = Rig::builtin("bimanual_ur5_sim").unwrap();
        ur5e.arms
            .iter_mut()
            .for_each(|a| a.model = scaledp_schema::RobotModel::Ur5e);
        rigs.extend([panda, ur5e]);
        for rig in &rigs {
            for seed in 0..4 {
                let r = run_episode(rig, seed, 20.0);
                let name = format!("{} ({})", rig.name, rig.arms[0].model);
                assert!(r.task.success, "{name} seed {seed}: {:?}", r.task);
                assert!(
                    r.operator_done,
                    "{name} seed {seed}: the operator never finished"
                );
                assert!(
                    (8.0..13.0).contains(&r.duration_s),
                    "{name} seed {seed}: {} s",
                    r.duration_s
                );
            }
        }
    }

    #[test]
    fn a_seed_fixes_the_hands_and_another_seed_changes_them() {
        let rig = Rig::builtin("franka_2zed").unwrap();
        let scene = Scene::new(&rig);
        let state = crate::world::World::new(&rig, 1).state();
        let samples = |seed: u64| {
            let mut op = ScriptedOperator::new(&scene, seed);
            op.begin(0.0);
            (0..50)
                .map(|k| op.command(k as f64 * 0.01, &scene, &state)[0].pose)
                .collect::<Vec<_>>()
        };
        assert_eq!(samples(3), samples(3));
        assert_ne!(samples(3), samples(4));
    }
}
