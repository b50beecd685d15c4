//! The world and the scripted operator in simulated time, with no cameras and no network: the
//! offline writer's clock, and the quick way to score the operator over many seeds.
//!
//! The operator samples its leader at [`LEADER_RATE_HZ`] from t = 0 (it begins at once); each
//! sample reaches the arm controllers 1–3 ms later (seeded), as over a local network.

use std::collections::VecDeque;
use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scaledp_schema::Rig;

use crate::operator::{ScriptedOperator, LEADER_RATE_HZ};
use crate::scene::Scene;
use crate::task::TaskState;
use crate::world::{ArmCommand, World};

/// World + operator advanced event by event in simulated time.
#[derive(Debug, Clone)]
pub struct OfflineRun {
    world: World,
    operator: ScriptedOperator,
    rng: ChaCha8Rng,
    period_ns: u64,
    next_sample_ns: u64,
    in_flight: VecDeque<(u64, Vec<ArmCommand>)>,
}

impl OfflineRun {
    /// Episode `seed` on `scene`, the operator starting at once.
    pub fn new(scene: Arc<Scene>, seed: u64) -> Self {
        let mut operator = ScriptedOperator::new(&scene, seed);
        operator.begin(0.0);
        Self {
            world: World::with_scene(scene, seed),
            operator,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x1EAD_E700),
            period_ns: (1e9 / LEADER_RATE_HZ).round() as u64,
            next_sample_ns: 0,
            in_flight: VecDeque::new(),
        }
    }

    /// Advances to `t_ns` (since the reset), calling `on_sample(stamp_ns, commands)` for every
    /// leader sample taken on the way (stamp = when the leader was read).
    pub fn advance_to(&mut self, t_ns: u64, on_sample: &mut dyn FnMut(u64, &[ArmCommand])) {
        loop {
            let delivery = self.in_flight.front().map_or(u64::MAX, |(t, _)| *t);
            let next = delivery.min(self.next_sample_ns);
            if next > t_ns {
                break;
            }
            self.step_to(next, &[]);
            if delivery <= self.next_sample_ns {
                if let Some((_, cmds)) = self.in_flight.pop_front() {
                    self.world.step(0.0, &cmds);
                }
            } else {
                let t_s = next as f64 * 1e-9;
                let state = self.world.state();
                let cmds = self.operator.command(t_s, self.world.scene(), &state);
                on_sample(next, &cmds);
                let latency = self.rng.random_range(1_000_000..3_000_000);
                self.in_flight.push_back((next + latency, cmds));
                self.next_sample_ns += self.period_ns;
            }
        }
        self.step_to(t_ns, &[]);
    }

    fn step_to(&mut self, t_ns: u64, cmds: &[ArmCommand]) {
        let dt = t_ns.saturating_sub(self.world.time_ns());
        self.world.step(dt as f64 * 1e-9, cmds);
    }

    /// The world.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// True when the operator has finished its demonstration.
    pub fn operator_done(&self) -> bool {
        self.operator.done()
    }
}

/// How one scripted episode ended.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeResult {
    /// The task at the end.
    pub task: TaskState,
    /// The operator finished before the time limit.
    pub operator_done: bool,
    /// Seconds until the operator finished (or the limit).
    pub duration_s: f64,
}

/// Runs the operator's episode `seed` on `rig` until it finishes or `max_s` pass.
pub fn run_episode(rig: &Rig, seed: u64, max_s: f64) -> EpisodeResult {
    run_on(Arc::new(Scene::new(rig)), seed, max_s)
}

/// [`run_episode`] on a shared scene.
pub fn run_on(scene: Arc<Scene>, seed: u64, max_s: f64) -> EpisodeResult {
    let mut run = OfflineRun::new(scene, seed);
    let step_ns = 10_000_000;
    let mut t = 0;
    while !run.operator_done() && (t as f64) < max_s * 1e9 {
        t += step_ns;
        run.advance_to(t, &mut |_, _| {});
    }
    EpisodeResult {
        task: run.world().task_state(),
        operator_done: run.operator_done(),
        duration_s: t as f64 * 1e-9,
    }
}
