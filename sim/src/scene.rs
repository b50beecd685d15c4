//! The scripted scene: every arm repeats a pick-and-place cycle in joint space, each cycle with
//! its own seeded pick and place spots, and carries a cube between them.
//!
//! `Scene::state_at(t)` is a pure function of the rig, the seed and `t`, so every stream (and
//! every test) sees the same world at the same instant.

use glam::{DMat4, DVec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scaledp_schema::rig::{Arm, Rig};
use scaledp_schema::RobotModel;

/// Seconds per pick-and-place cycle.
pub const CYCLE_S: f64 = 8.0;

/// One arm at one instant.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmState {
    /// Joint positions (rad), in the rig's joint order.
    pub q: Vec<f64>,
    /// Gripper opening (m).
    pub gripper_width_m: f64,
    /// `world_from_base` of this arm.
    pub world_from_base: DMat4,
    /// Cube centre in the world frame.
    pub cube_world: DVec3,
}

/// The whole scene at one instant.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneState {
    /// Per arm, in rig order.
    pub arms: Vec<ArmState>,
}

/// The scene of a rig under a seed.
#[derive(Debug, Clone)]
pub struct Scene {
    arms: Vec<(Arm, DMat4)>,
    seed: u64,
}

/// (start, end, joints from, joints to, gripper from, gripper to); times are cycle fractions.
type Segment<'a> = (f64, f64, &'a [f64], &'a [f64], f64, f64);

/// Minimum-jerk blend 0 → 1 (zero velocity and acceleration at both ends).
fn min_jerk(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)
}

fn home(model: RobotModel) -> Vec<f64> {
    match model {
        RobotModel::Fr3 | RobotModel::Panda => vec![0.0, -0.3, 0.0, -2.2, 0.0, 1.95, 0.785],
        RobotModel::Ur5 | RobotModel::Ur5e => vec![0.0, -1.9, 1.9, -1.57, -1.57, 0.0],
    }
}

/// Joint offsets that lower the tool towards the table from `home` (reach down and out).
fn reach(model: RobotModel) -> Vec<f64> {
    match model {
        RobotModel::Fr3 | RobotModel::Panda => vec![0.0, 0.8, 0.0, 0.3, 0.0, 0.5, 0.0],
        RobotModel::Ur5 | RobotModel::Ur5e => vec![0.0, 0.5, 0.35, -0.85, 0.0, 0.0],
    }
}

impl Scene {
    /// Places arm `i` of `n` along the world y axis, 0.7 m apart, first arm at +y (left).
    pub fn new(rig: &Rig, seed: u64) -> Self {
        let n = rig.arms.len() as f64;
        let arms = rig
            .arms
            .iter()
            .enumerate()
            .map(|(i, a)| {
                let y = ((n - 1.0) / 2.0 - i as f64) * 0.7;
                (a.clone(), DMat4::from_translation(DVec3::new(0.0, y, 0.0)))
            })
            .collect();
        Self { arms, seed }
    }

    /// Joint configuration of a cycle's pick (or place) spot, within the model's limits.
    fn spot(&self, arm: usize, cycle: u64, place: bool) -> Vec<f64> {
        let model = self.arms[arm].0.model;
        let mut rng = ChaCha8Rng::seed_from_u64(
            self.seed ^ (cycle << 8) ^ ((arm as u64) << 4) ^ u64::from(place),
        );
        let side = if place { -1.0 } else { 1.0 };
        let mut q = home(model);
        q[0] += side * rng.random_range(0.25..0.55);
        for (qi, r) in q.iter_mut().zip(reach(model)) {
            *qi += r * rng.random_range(0.85..1.0);
        }
        clamp_to_limits(model, &mut q);
        q
    }

    /// Rest, above-pick, pick, above-place, place configurations and gripper widths over one cycle.
    fn cycle_state(&self, arm: usize, t_s: f64) -> (Vec<f64>, f64, Vec<f64>, Vec<f64>, f64) {
        let (a, _) = &self.arms[arm];
        let cycle = (t_s / CYCLE_S).floor().max(0.0) as u64;
        let u = t_s / CYCLE_S - cycle as f64;
        let rest = home(a.model);
        let pick = self.spot(arm, cycle, false);
        let place = self.spot(arm, cycle, true);
        let above = |q: &[f64]| -> Vec<f64> {
            q.iter()
                .zip(&rest)
                .map(|(x, h)| x + 0.35 * (h - x))
                .collect()
        };
        let (pick_up, place_up) = (above(&pick), above(&place));
        let open = a.gripper.as_ref().map_or(0.08, |g| g.model.max_width_m());
        let closed = 0.045;
        let segments: [Segment; 9] = [
            (0.00, 0.15, &rest, &pick_up, open, open),
            (0.15, 0.25, &pick_up, &pick, open, open),
            (0.25, 0.32, &pick, &pick, open, closed),
            (0.32, 0.42, &pick, &pick_up, closed, closed),
            (0.42, 0.62, &pick_up, &place_up, closed, closed),
            (0.62, 0.70, &place_up, &place, closed, closed),
            (0.70, 0.76, &place, &place, closed, open),
            (0.76, 0.86, &place, &place_up, open, open),
            (0.86, 1.00, &place_up, &rest, open, open),
        ];
        let seg = segments.iter().find(|s| u < s.1).unwrap_or(&segments[8]);
        let s = min_jerk((u - seg.0) / (seg.1 - seg.0));
        let q = seg
            .2
            .iter()
            .zip(seg.3)
            .map(|(a, b)| a + s * (b - a))
            .collect();
        let width = seg.4 + s * (seg.5 - seg.4);
        (q, width, pick, place, u)
    }

    fn tcp_world(&self, arm: usize, q: &[f64]) -> DVec3 {
        let (a, world_from_base) = &self.arms[arm];
        let flange = a.model.base_from_flange(q).unwrap_or(DMat4::IDENTITY);
        (*world_from_base * flange * flange_from_fingertips(a))
            .w_axis
            .truncate()
    }

    /// The scene at `t_s` seconds after the simulation's start.
    pub fn state_at(&self, t_s: f64) -> SceneState {
        let arms = (0..self.arms.len())
            .map(|i| {
                let (q, width, pick, place, u) = self.cycle_state(i, t_s);
                let (_, world_from_base) = &self.arms[i];
                let cube_world = if u < 0.28 {
                    self.tcp_world(i, &pick)
                } else if u < 0.73 {
                    self.tcp_world(i, &q)
                } else {
                    self.tcp_world(i, &place)
                };
                ArmState {
                    q,
                    gripper_width_m: width,
                    world_from_base: *world_from_base,
                    cube_world,
                }
            })
            .collect();
        SceneState { arms }
    }

    /// The arms and their placements.
    pub fn arms(&self) -> impl Iterator<Item = (&Arm, &DMat4)> {
        self.arms.iter().map(|(a, t)| (a, t))
    }
}

/// Where the simulated fingertips close: the Franka Hand's TCP, or 15 cm ahead of a UR's tool0
/// for a Robotiq 2F-85.
pub fn flange_from_fingertips(arm: &Arm) -> DMat4 {
    match arm.model {
        RobotModel::Fr3 | RobotModel::Panda => arm.model.default_flange_from_tcp(),
        RobotModel::Ur5 | RobotModel::Ur5e => DMat4::from_translation(DVec3::new(0.0, 0.0, 0.15)),
    }
}

fn clamp_to_limits(model: RobotModel, q: &mut [f64]) {
    for (x, (lo, hi)) in q.iter_mut().zip(model.joint_limits()) {
        *x = x.clamp(lo + 0.05, hi - 0.05);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cube_waits_at_the_pick_rides_in_the_fingers_and_stays_at_the_place() {
        for name in Rig::builtin_names() {
            let rig = Rig::builtin(name).unwrap();
            let scene = Scene::new(&rig, 11);
            let mut picks = Vec::new();
            for cycle in 0..3 {
                let at = |u: f64| scene.state_at((f64::from(cycle) + u) * CYCLE_S);
                for arm in 0..rig.arms.len() {
                    let cube = |u: f64| at(u).arms[arm].cube_world;
                    let fingers = |u: f64| scene.tcp_world(arm, &at(u).arms[arm].q);
                    let width = |u: f64| at(u).arms[arm].gripper_width_m;
                    let (pick, place) = (cube(0.0), cube(0.8));
                    for u in [0.05, 0.2, 0.27] {
                        assert_eq!(cube(u), pick, "{name}: the cube moved before the grasp");
                    }
                    assert!(
                        (fingers(0.25) - pick).length() < 1e-9,
                        "{name}: missed the cube"
                    );
                    assert!(width(0.3) < width(0.2), "{name}: the gripper did not close");
                    for u in [0.35, 0.5, 0.65] {
                        assert!(
                            (fingers(u) - cube(u)).length() < 1e-9,
                            "{name}: the cube left the fingers at {u}"
                        );
                    }
                    assert!((fingers(0.74) - place).length() < 1e-9);
                    for u in [0.9, 0.99] {
                        assert_eq!(cube(u), place, "{name}: the cube moved after the place");
                    }
                    assert!((place - pick).length() > 0.05, "{name}: carried nowhere");
                    picks.push(pick);
                }
            }
            // Each cycle and each arm has its own pick spot.
            for (i, a) in picks.iter().enumerate() {
                assert!(picks[i + 1..].iter().all(|b| (*a - *b).length() > 1e-3));
            }
            let other = Scene::new(&rig, 12).state_at(0.0);
            assert_ne!(
                other.arms[0].cube_world,
                scene.state_at(0.0).arms[0].cube_world
            );
        }
    }

    #[test]
    fn motion_is_smooth_deterministic_and_within_limits() {
        for name in Rig::builtin_names() {
            let rig = Rig::builtin(name).unwrap();
            let scene = Scene::new(&rig, 7);
            let mut prev = scene.state_at(0.0);
            for k in 1..4000 {
                let t = k as f64 * 0.01;
                let s = scene.state_at(t);
                assert_eq!(s, Scene::new(&rig, 7).state_at(t));
                for (a, (b, (arm, _))) in s.arms.iter().zip(prev.arms.iter().zip(scene.arms())) {
                    for ((x, y), (lo, hi)) in a.q.iter().zip(&b.q).zip(arm.model.joint_limits()) {
                        assert!((lo..=hi).contains(&x), "{name}: {x} outside [{lo}, {hi}]");
                        assert!(
                            (x - y).abs() < 0.05,
                            "{name}: joint jumps {y} -> {x} at {t}"
                        );
                    }
                }
                prev = s;
            }
        }
    }
}
