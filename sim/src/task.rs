//! The pick-and-place task: one cube and one target marker per arm (a two-cube task on a
//! bimanual rig), drawn from the seed; grasping, carrying, releasing and the scorer.
//!
//! Grasp model: while the fingers close, a cube whose centre lies between them (within the
//! finger pads across, and no deeper than the finger length) is pushed to the middle by the
//! first finger that touches it and held once the opening reaches the cube's width; the
//! fingers then stop there. A held cube rides rigidly with the fingertips (only its yaw is
//! kept: it stays upright) and never sinks into the table. When the fingers open past the
//! cube it is released and falls freely onto the table. Cubes do not collide with each other
//! or with the arm, and an empty closing gripper passes through nothing: it just closes.
//!
//! Success: every cube rests on the table, released, with its centre within
//! [`SUCCESS_RADIUS_M`] (horizontally) of its target.

use glam::{DMat4, DVec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::scene::{Scene, CUBE_HALF_M, TABLE_Z_M};

/// Largest horizontal distance (m) from a cube's centre to its target that counts as placed.
pub const SUCCESS_RADIUS_M: f64 = 0.03;
/// Smallest distance (m) between a cube's start and its target.
pub const MIN_TRAVEL_M: f64 = 0.10;
const GRAVITY_MPS2: f64 = 9.81;

/// One cube and its target.
#[derive(Debug, Clone, PartialEq)]
pub struct Cube {
    /// Centre (world, m).
    pub position: DVec3,
    /// Rotation about the vertical (rad).
    pub yaw: f64,
    /// Where it must go: a marker on the table (world, m; z on the table top).
    pub target: DVec3,
    /// The arm holding it.
    pub held_by: Option<usize>,
    /// The cube's pose in the holding fingertips' frame.
    fingertips_from_cube: DMat4,
    /// Vertical speed while falling (m/s).
    vz: f64,
}

impl Cube {
    /// On the table, released and still.
    pub fn resting(&self) -> bool {
        self.held_by.is_none() && self.position.z <= TABLE_Z_M + CUBE_HALF_M + 1e-9
    }
    /// Horizontal distance from the target (m).
    pub fn distance_to_target_m(&self) -> f64 {
        (self.position - self.target).truncate().length()
    }
    /// Resting within [`SUCCESS_RADIUS_M`] of the target.
    pub fn placed(&self) -> bool {
        self.resting() && self.distance_to_target_m() <= SUCCESS_RADIUS_M
    }
}

/// What an evaluation harness reads about one cube (JSON on the status key).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CubeState {
    /// Centre (world, m).
    pub position_m: [f64; 3],
    /// Rotation about the vertical (rad).
    pub yaw_rad: f64,
    /// The target marker's centre (world, m).
    pub target_m: [f64; 3],
    /// The arm holding it, if any.
    pub held_by: Option<usize>,
    /// On the table, released.
    pub resting: bool,
    /// Horizontal distance to the target (m).
    pub distance_m: f64,
    /// Resting within 3 cm of the target.
    pub placed: bool,
}

/// The task's privileged state: what a scorer or an evaluation harness may read (a policy sees
/// only the cameras and the joints).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TaskState {
    /// The episode's seed.
    pub seed: u64,
    /// Seconds since the episode's reset.
    pub t_s: f64,
    /// Per cube (cube i is arm i's).
    pub cubes: Vec<CubeState>,
    /// Every cube placed, now.
    pub success: bool,
    /// When the task last became a success (s since the reset), while it still is one.
    pub time_to_success_s: Option<f64>,
}

/// The cubes of one episode and their scoring.
#[derive(Debug, Clone)]
pub struct Task {
    seed: u64,
    /// One per arm.
    pub cubes: Vec<Cube>,
    success_since_ns: Option<u64>,
}

/// A uniform point of arm `arm`'s work region.
fn draw(rng: &mut ChaCha8Rng, scene: &Scene, arm: usize) -> DVec3 {
    let a = &scene.arms()[arm];
    a.region_center
        + DVec3::new(
            rng.random_range(-a.region_half.x..=a.region_half.x),
            rng.random_range(-a.region_half.y..=a.region_half.y),
            0.0,
        )
}

impl Task {
    /// Cube and target positions of `seed`: uniform in each arm's work region, at least
    /// [`MIN_TRAVEL_M`] apart. The cubes start square to the world axes.
    pub fn new(scene: &Scene, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7A5C_0000_C0BE);
        let cubes = (0..scene.arms().len())
            .map(|i| {
                let start = draw(&mut rng, scene, i);
                let mut target = draw(&mut rng, scene, i);
                while (target - start).length() < MIN_TRAVEL_M {
                    target = draw(&mut rng, scene, i);
                }
                Cube {
                    position: start + DVec3::Z * CUBE_HALF_M,
                    yaw: 0.0,
                    target,
                    held_by: None,
                    fingertips_from_cube: DMat4::IDENTITY,
                    vz: 0.0,
                }
            })
            .collect();
        Self {
            seed,
            cubes,
            success_since_ns: None,
        }
    }

    /// Released cubes fall for `dt_s` and stop on the table.
    pub fn fall(&mut self, dt_s: f64) {
        let rest_z = TABLE_Z_M + CUBE_HALF_M;
        for c in &mut self.cubes {
            if c.held_by.is_some() || c.position.z <= rest_z {
                continue;
            }
            c.vz -= GRAVITY_MPS2 * dt_s;
            c.position.z += c.vz * dt_s;
            if c.position.z <= rest_z {
                c.position.z = rest_z;
                c.vz = 0.0;
            }
        }
    }

    /// One gripper tick of arm `arm`: the opening moves from `*width_m` towards `command_m` by at
    /// most `step_m`, grasping, carrying or releasing as described in the module docs.
    pub fn gripper_tick(
        &mut self,
        arm: usize,
        world_from_fingertips: &DMat4,
        width_m: &mut f64,
        command_m: f64,
        step_m: f64,
    ) {
        let cube_width = 2.0 * CUBE_HALF_M;
        if let Some(c) = self.cubes.iter_mut().find(|c| c.held_by == Some(arm)) {
            let pose = *world_from_fingertips * c.fingertips_from_cube;
            c.position = pose.w_axis.truncate();
            c.position.z = c.position.z.max(TABLE_Z_M + CUBE_HALF_M);
            c.yaw = pose.x_axis.y.atan2(pose.x_axis.x);
            if command_m > cube_width + 0.002 {
                *width_m = (*width_m + step_m).min(command_m);
                if *width_m > cube_width + 0.002 {
                    c.held_by = None;
                    c.vz = 0.0;
                }
            } else {
                *width_m = cube_width;
            }
            return;
        }
        if command_m >= *width_m {
            *width_m = (*width_m + step_m).min(command_m);
            return;
        }
        let mut next = (*width_m - step_m).max(command_m).max(0.0);
        let fingertips_from_world = world_from_fingertips.inverse();
        for c in &mut self.cubes {
            if c.held_by.is_some() {
                continue;
            }
            let mut local = fingertips_from_world.transform_point3(c.position);
            let between = local.x.abs() <= CUBE_HALF_M + 0.005
                && (-0.045..=0.012).contains(&local.z)
                && local.y.abs() <= *width_m / 2.0;
            if !between || next / 2.0 > local.y.abs() + CUBE_HALF_M {
                continue;
            }
            // A finger touches the cube and pushes it towards the middle.
            local.y = local.y.signum() * (next / 2.0 - CUBE_HALF_M).max(0.0);
            c.position = world_from_fingertips.transform_point3(local);
            if next <= cube_width {
                next = cube_width;
                c.held_by = Some(arm);
                c.vz = 0.0;
                let cube_pose = DMat4::from_translation(c.position) * DMat4::from_rotation_z(c.yaw);
                c.fingertips_from_cube = fingertips_from_world * cube_pose;
            }
            break;
        }
        *width_m = next;
    }

    /// Updates the success clock at `t_ns` (since the reset).
    pub fn score(&mut self, t_ns: u64) {
        let success = !self.cubes.is_empty() && self.cubes.iter().all(Cube::placed);
        self.success_since_ns = match (success, self.success_since_ns) {
            (true, None) => Some(t_ns),
            (true, since) => since,
            (false, _) => None,
        };
    }

    /// The privileged state at `t_ns`.
    pub fn state(&self, t_ns: u64) -> TaskState {
        TaskState {
            seed: self.seed,
            t_s: t_ns as f64 * 1e-9,
            cubes: self
                .cubes
                .iter()
                .map(|c| CubeState {
                    position_m: c.position.to_array(),
                    yaw_rad: c.yaw,
                    target_m: c.target.to_array(),
                    held_by: c.held_by,
                    resting: c.resting(),
                    distance_m: c.distance_to_target_m(),
                    placed: c.placed(),
                })
                .collect(),
            success: self.success_since_ns.is_some(),
            time_to_success_s: self.success_since_ns.map(|t| t as f64 * 1e-9),
        }
    }

    /// The episode's seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }
}

#[cfg(test)]
mod tests {
    use scaledp_schema::Rig;

    use super::*;

    #[test]
    fn seeds_draw_distinct_cubes_and_targets_inside_the_regions() {
        for name in Rig::builtin_names() {
            let rig = Rig::builtin(name).unwrap();
            let scene = Scene::new(&rig);
            let mut starts = Vec::new();
            for seed in 0..50 {
                let task = Task::new(&scene, seed);
                assert_eq!(task.cubes.len(), rig.arms.len());
                for (c, a) in task.cubes.iter().zip(scene.arms()) {
                    for p in [c.position, c.target] {
                        let d = (p - a.region_center).truncate().abs();
                        assert!(d.x <= a.region_half.x + 1e-12 && d.y <= a.region_half.y + 1e-12);
                    }
                    assert!(c.distance_to_target_m() >= MIN_TRAVEL_M);
                    assert!(c.resting() && !c.placed());
                    starts.push(c.position);
                }
                assert_eq!(
                    Task::new(&scene, seed).cubes,
                    task.cubes,
                    "a seed fixes the task"
                );
            }
            for (i, a) in starts.iter().enumerate() {
                assert!(starts[i + 1..].iter().all(|b| (*a - *b).length() > 1e-6));
            }
        }
    }

    #[test]
    fn a_released_cube_falls_onto_the_table_and_stops() {
        let scene = Scene::new(&Rig::builtin("franka_2zed").unwrap());
        let mut task = Task::new(&scene, 1);
        task.cubes[0].position.z = 0.2;
        assert!(!task.cubes[0].resting());
        let mut t = 0.0;
        while !task.cubes[0].resting() {
            task.fall(0.001);
            t += 0.001;
            assert!(t < 1.0, "still falling after a second");
        }
        // Free fall over 17.75 cm takes about 0.19 s.
        assert!(
            (t - (2.0 * 0.1775 / GRAVITY_MPS2).sqrt()).abs() < 0.01,
            "{t} s"
        );
        assert_eq!(task.cubes[0].position.z, CUBE_HALF_M);
    }
}
