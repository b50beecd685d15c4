//! A bridge simulator live on Zenoh (`scaledp sim --rig metaworld/<task>`): stepped in a loop of
//! its own, publishing every step's cameras and joints as the rig's topics and the simulation's
//! time on `/clock` (`rosgraph_msgs/msg/Clock`, what ROS nodes follow under `use_sim_time`),
//! taking the latest command of each arm from the rig's command topics (or, with the scripted
//! expert, publishing the expert's commands there), resetting on `<prefix>/reset` and reporting
//! the task on `<prefix>/task`.
//!
//! The simulation advances as fast as the simulator steps and renders, never ahead of real
//! time: a policy served on `/clock` acts asynchronously, its inference latency costing
//! simulated time as it would cost real time on a robot. On a machine that cannot render every
//! camera at the rig's rate in real time the simulation runs slower than real time (its
//! `/clock` says how much); stamps are on the simulation's clock, so nothing downstream sees a
//! gap.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use scaledp_recorder::keys::{bridge_key, rmw_key_expr};
use scaledp_recorder::now_ns;
use scaledp_schema::msg::{Clock, JointState, PoseStamped, Time};
use scaledp_schema::rig::CommandType;
use scaledp_schema::{Rig, RosMessage};
use serde::Serialize;
use zenoh::sample::Sample;
use zenoh::Wait;

use super::episodes::Publishers;
use super::Bridge;
use crate::world::ArmCommand;
use crate::{messages, Error, KeyStyle, Result};

/// How a live bridge runs.
#[derive(Debug, Clone)]
pub struct LiveOptions {
    /// The rig (with a `[simulator]`).
    pub rig: Rig,
    /// Key style of its topics.
    pub keys: KeyStyle,
    /// Bridge namespace (bridge keys only).
    pub namespace: String,
    /// Prefix of `<prefix>/reset` and `<prefix>/task`.
    pub control_prefix: String,
    /// The first episode's seed.
    pub seed: u64,
    /// The simulator's scripted expert drives the arms (and its commands are published).
    pub expert: bool,
    /// The simulated clock's topic.
    pub clock_topic: String,
}

impl LiveOptions {
    /// Bridge keys, `scaledp/sim` control keys, seed 0, no expert, `/clock`.
    pub fn new(rig: Rig) -> Self {
        LiveOptions {
            rig,
            keys: KeyStyle::Bridge,
            namespace: String::new(),
            control_prefix: "scaledp/sim".into(),
            seed: 0,
            expert: false,
            clock_topic: "/clock".into(),
        }
    }
}

/// The episode as it stands (the `<prefix>/task` JSON).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct LiveTask {
    /// The episode's seed.
    pub seed: u64,
    /// Steps since its reset.
    pub step: u64,
    /// Simulated seconds since its reset.
    pub t_s: f64,
    /// Successful now.
    pub success: bool,
    /// When it first succeeded (simulated s).
    pub time_to_success_s: Option<f64>,
    /// The simulator's last step is taken.
    pub done: bool,
    /// Simulated seconds per wall-clock second over the last full second (over the run so far
    /// until a second has passed).
    pub real_time_factor: f64,
    /// The furthest stage of the episode so far, for a simulator that names stages
    /// ([`super::Hello::stages`]).
    pub highest_stage: Option<f64>,
}

struct Shared {
    stop: AtomicBool,
    /// When the bridge started, and the loop's last round in ms after it: a hung simulator
    /// process stops the rounds ([`LiveBridge::check`]).
    born: Instant,
    round_ms: AtomicU64,
    pending: Mutex<Vec<ArmCommand>>,
    /// Commands stamped before this (the current episode's start) are dropped.
    episode_start_ns: AtomicU64,
    reset: Mutex<Option<u64>>,
    task: Mutex<LiveTask>,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// How long a live simulator may answer nothing before it is taken for hung (an ALOHA reset,
/// its longest call, plans the expert's 400 steps).
pub const STALL: Duration = Duration::from_secs(60);

/// A running live bridge.
pub struct LiveBridge {
    hello: super::Hello,
    killer: super::Killer,
    shared: Arc<Shared>,
    thread: Option<JoinHandle<Result<()>>>,
    _subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
}

impl LiveBridge {
    /// Starts the simulator of `opts.rig` and its loop on `session`.
    pub fn spawn(opts: LiveOptions, session: &zenoh::Session) -> Result<Self> {
        let bridge = Bridge::spawn(&opts.rig)?;
        let hello = bridge.hello().clone();
        let killer = bridge.killer();
        let rig = opts.rig.clone();
        let shared = Arc::new(Shared {
            stop: AtomicBool::new(false),
            born: Instant::now(),
            round_ms: AtomicU64::new(0),
            pending: Mutex::new(vec![ArmCommand::default(); rig.arms.len()]),
            episode_start_ns: AtomicU64::new(0),
            reset: Mutex::new(None),
            task: Mutex::new(LiveTask {
                seed: opts.seed,
                ..LiveTask::default()
            }),
        });
        let zerr = |key: &str| {
            let key = key.to_string();
            move |e: zenoh::Error| Error::Zenoh {
                key: key.clone(),
                reason: e.to_string(),
            }
        };
        let mut subscribers = Vec::new();
        if !opts.expert {
            for (i, arm) in rig.arms.iter().enumerate() {
                let mut topics = Vec::new();
                if let Some(t) = &arm.command_topic {
                    let ty = arm.command_type.unwrap_or_default().message_type();
                    topics.push((t.clone(), ty, false));
                }
                if let Some(t) = arm.gripper.as_ref().and_then(|g| g.command_topic.clone()) {
                    topics.push((t, "sensor_msgs/msg/JointState", true));
                }
                for (topic, ty, gripper) in topics {
                    for key in [
                        bridge_key(&opts.namespace, &topic),
                        rmw_key_expr(&topic, ty),
                    ] {
                        let (sh, arm) = (shared.clone(), arm.clone());
                        let sub = session
                            .declare_subscriber(key.clone())
                            .callback(move |s: Sample| command(&sh, i, &arm, gripper, &s))
                            .wait()
                            .map_err(zerr(&key))?;
                        subscribers.push(sub);
                    }
                }
            }
        }
        let reset_key = format!("{}/reset", opts.control_prefix.trim_matches('/'));
        let sh = shared.clone();
        subscribers.push(
            session
                .declare_subscriber(reset_key.clone())
                .callback(move |s: Sample| {
                    let text = String::from_utf8_lossy(&s.payload().to_bytes())
                        .trim()
                        .to_string();
                    let current = lock(&sh.task).seed;
                    match text.parse::<u64>() {
                        Ok(seed) => *lock(&sh.reset) = Some(seed),
                        Err(_) if text.is_empty() => *lock(&sh.reset) = Some(current + 1),
                        Err(_) => tracing::warn!("{}: not a seed: {text:?}", s.key_expr()),
                    }
                })
                .wait()
                .map_err(zerr(&reset_key))?,
        );
        let pubs = Publishers::declare(session, &rig, opts.keys, &opts.namespace)?;
        let clock_key = bridge_key(&opts.namespace, &opts.clock_topic);
        let clock = session
            .declare_publisher(clock_key.clone())
            .wait()
            .map_err(zerr(&clock_key))?;
        let task_key = format!("{}/task", opts.control_prefix.trim_matches('/'));
        let status = session
            .declare_publisher(task_key.clone())
            .wait()
            .map_err(zerr(&task_key))?;
        let sh = shared.clone();
        let thread = std::thread::Builder::new()
            .name("sim:bridge".into())
            .spawn(move || run(bridge, pubs, clock, status, &sh, &opts))
            .map_err(|source| Error::Thread {
                topic: "bridge".into(),
                source,
            })?;
        Ok(LiveBridge {
            hello,
            killer,
            shared,
            thread: Some(thread),
            _subscribers: subscribers,
        })
    }

    /// What the simulator said of itself.
    pub fn hello(&self) -> &super::Hello {
        &self.hello
    }

    /// Starts the episode of `seed` at the loop's next step.
    pub fn reset(&self, seed: u64) {
        *lock(&self.shared.reset) = Some(seed);
    }

    /// The episode as it stands.
    pub fn task(&self) -> LiveTask {
        lock(&self.shared.task).clone()
    }

    /// An error once the loop has ended on its own (its simulator process failed: that error)
    /// or has not come round for `stall` (a hung simulator, which is then killed); `Ok` while it
    /// runs. Whoever waits on [`LiveBridge::task`] checks this too, or waits for ever on a dead
    /// simulator. [`STALL`] is the limit `eval --live` and `scaledp sim` use.
    pub fn check(&mut self, stall: Duration) -> Result<()> {
        if self.thread.as_ref().is_some_and(JoinHandle::is_finished) {
            return Err(match self.thread.take().map(JoinHandle::join) {
                Some(Ok(Err(e))) => e,
                Some(Err(_)) => ended("its thread panicked"),
                _ => ended("its loop ended"),
            });
        }
        let quiet = || {
            let round = Duration::from_millis(self.shared.round_ms.load(Ordering::Relaxed));
            self.shared.born.elapsed().saturating_sub(round)
        };
        // Looked at twice: a process stopped (SIGSTOP) past `stall` resumes with its loop a
        // round behind, which one look would take for a hang.
        if quiet() > stall {
            std::thread::sleep(Duration::from_millis(300));
            let q = quiet();
            if q > stall {
                self.killer.kill();
                return Err(ended(&format!(
                    "the simulator answered nothing for {:.0} s, and was killed",
                    q.as_secs_f64()
                )));
            }
        }
        Ok(())
    }

    /// Stops the loop (and the simulator) and reports how it ended.
    pub fn stop(mut self) -> Result<()> {
        self.shared.stop.store(true, Ordering::Relaxed);
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(r)) => r,
            Some(Err(_)) => Err(ended("its thread panicked")),
            None => Ok(()),
        }
    }
}

fn ended(reason: &str) -> Error {
    Error::Bridge {
        what: "the live bridge".into(),
        reason: reason.into(),
    }
}

impl Drop for LiveBridge {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
    }
}

/// A command message for arm `i` (its pose target, or with `gripper` its gripper's).
fn command(sh: &Shared, i: usize, arm: &scaledp_schema::rig::Arm, gripper: bool, s: &Sample) {
    let bytes = s.payload().to_bytes();
    let start = sh.episode_start_ns.load(Ordering::Relaxed);
    let mut pending = lock(&sh.pending);
    let Some(slot) = pending.get_mut(i) else {
        return;
    };
    if gripper {
        let (Ok(js), Some(g)) = (JointState::from_cdr(&bytes), arm.gripper.as_ref()) else {
            return;
        };
        if js.header.stamp.as_ns() >= start {
            slot.gripper_width_m = messages::read_gripper_command(g, &js).or(slot.gripper_width_m);
        }
    } else if arm.command_type == Some(CommandType::JointState) {
        // A leader arm's joints: passed through as joint targets.
        if let Ok(js) = JointState::from_cdr(&bytes) {
            if js.header.stamp.as_ns() >= start {
                if let Some(q) = messages::read_joints(arm, &js) {
                    slot.joints = Some(q);
                    slot.pose = None;
                }
            }
        }
    } else if let Ok(p) = PoseStamped::from_cdr(&bytes) {
        if p.header.stamp.as_ns() >= start {
            slot.pose = messages::read_pose_command(&p).or(slot.pose);
        }
    }
}

/// The loop: reset, then step, publish, pace, until stopped.
fn run(
    mut bridge: Bridge,
    mut pubs: Publishers,
    clock: zenoh::pubsub::Publisher<'static>,
    status: zenoh::pubsub::Publisher<'static>,
    sh: &Shared,
    opts: &LiveOptions,
) -> Result<()> {
    let dt = bridge.step_ns();
    // The simulated clock: an epoch time now, advancing one step per step, across resets.
    let mut sim_ns = now_ns();
    let wall0 = Instant::now();
    let sim0 = sim_ns;
    let mut seed = opts.seed;
    let mut episode_ns = sim_ns;
    let mut obs = bridge.reset(seed, true)?;
    let mut success_at = None;
    let staged = !bridge.hello().stages.is_empty();
    let mut highest: Option<f64> = None;
    let (mut last_status, mut rtf_mark) = (Instant::now(), (Instant::now(), sim_ns));
    // The last full second's rate, once a second has passed.
    let mut rtf_full: Option<f64> = None;
    while !sh.stop.load(Ordering::Relaxed) {
        let round = sh.born.elapsed().as_millis();
        sh.round_ms
            .store(u64::try_from(round).unwrap_or(u64::MAX), Ordering::Relaxed);
        if let Some(s) = lock(&sh.reset).take() {
            seed = s;
            sim_ns += dt;
            episode_ns = sim_ns;
            sh.episode_start_ns.store(episode_ns, Ordering::Relaxed);
            *lock(&sh.pending) = vec![ArmCommand::default(); opts.rig.arms.len()];
            obs = bridge.reset(seed, true)?;
            success_at = None;
            highest = None;
        }
        let stamp = episode_ns + obs.step * dt;
        sim_ns = sim_ns.max(stamp);
        pubs.observation(&obs, stamp)?;
        let _ = clock
            .put(
                Clock {
                    clock: Time::from_ns(stamp),
                }
                .to_cdr(),
            )
            .wait();
        if obs.success && success_at.is_none() {
            success_at = Some(obs.step);
        }
        if staged {
            highest = Some(highest.map_or(obs.stage, |h: f64| h.max(obs.stage)));
        }
        let window_s = rtf_mark.0.elapsed().as_secs_f64();
        let window_rtf = (stamp - rtf_mark.1) as f64 / 1e9 / window_s.max(1e-9);
        if window_s >= 1.0 {
            rtf_full = Some(window_rtf);
            rtf_mark = (Instant::now(), stamp);
        }
        // Before the first full second (a short run on a fast machine), the rate so far.
        let rtf = rtf_full.unwrap_or(window_rtf);
        let s = dt as f64 * 1e-9;
        *lock(&sh.task) = LiveTask {
            seed,
            step: obs.step,
            t_s: obs.step as f64 * s,
            success: obs.success,
            time_to_success_s: success_at.map(|k| k as f64 * s),
            done: obs.done,
            real_time_factor: rtf,
            highest_stage: highest,
        };
        if last_status.elapsed() >= Duration::from_millis(100) {
            last_status = Instant::now();
            if let Ok(json) = serde_json::to_string(&*lock(&sh.task)) {
                let _ = status.put(json).wait();
            }
        }
        // Never ahead of real time.
        let due = wall0 + Duration::from_nanos(stamp - sim0);
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        if obs.done {
            // The simulator's episode is over: hold until a reset.
            std::thread::sleep(Duration::from_millis(20));
            continue;
        }
        obs = if opts.expert {
            let o = bridge.expert_step(true)?;
            pubs.commands(&o.commands, stamp)?;
            o
        } else {
            let cmds = lock(&sh.pending).clone();
            bridge.step(&cmds, true)?
        };
    }
    Ok(())
}
