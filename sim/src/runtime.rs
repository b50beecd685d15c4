//! The live simulator: the [`World`] stepped in real time on its own thread at the fastest
//! arm's controller rate, commands taken from Zenoh, measurements published by the stream
//! threads, the task's state on a status key, resets on a reset key, and (optionally) the
//! scripted operator on a thread of its own, sending its leader samples over Zenoh like any
//! other teleoperator or policy would.
//!
//! Keys (prefix [`SimOptions::control_prefix`], default `scaledp/sim`):
//! - `<prefix>/reset` (in): payload a seed in decimal (empty: the current seed + 1). Resets the
//!   world to that seed; with an operator, it starts demonstrating half a second later.
//! - `<prefix>/task` (out, 10 Hz): the task's state as JSON ([`TaskState`] plus `operator`:
//!   `null`, `"waiting"`, `"running"` or `"done"`).
//!
//! Command topics (the rig's `command_topic`s) are subscribed both as zenoh-bridge-ros2dds and
//! as rmw_zenoh publish them. A pose command stamped before the latest reset (and not zero) is
//! dropped, so a command in flight cannot drag a freshly reset arm back.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use scaledp_recorder::keys::{bridge_key, rmw_key, rmw_key_expr, RmwAttachment};
use scaledp_recorder::now_ns;
use scaledp_schema::rig::{CommandType, Rig};
use scaledp_schema::RosMessage;
use zenoh::qos::CongestionControl;
use zenoh::sample::Sample;
use zenoh::Wait;

use crate::error::{Error, Result};
use crate::headless::EpisodeResult;
use crate::key_style::KeyStyle;
use crate::latched::{LatchedCache, LatchedPublisher};
use crate::operator::ScriptedOperator;
use crate::render::View;
use crate::scene::Scene;
use crate::task::TaskState;
use crate::world::{ArmCommand, World, WorldState};

mod workers;

pub use workers::PublishHook;
pub(crate) use workers::Shared;
use workers::{lock, on_command, operator_loop, world_loop, OperatorSlot};

/// Settings of a simulation run; `spawn` starts it.
#[derive(Clone)]
pub struct SimOptions {
    rig: Rig,
    seed: u64,
    start_time_ns: Option<u64>,
    keys: KeyStyle,
    namespace: String,
    hook: Option<PublishHook>,
    frame_cache: usize,
    operator: bool,
    autoplay: bool,
    control_prefix: String,
    latched: Option<LatchedCache>,
}

impl SimOptions {
    /// Simulates `rig` reset to seed 0, bridge keys, starting now, no operator (the arms hold
    /// still until commanded), control keys under `scaledp/sim`.
    pub fn new(rig: Rig) -> Self {
        Self {
            rig,
            seed: 0,
            start_time_ns: None,
            keys: KeyStyle::Bridge,
            namespace: String::new(),
            hook: None,
            frame_cache: 0,
            operator: false,
            autoplay: false,
            control_prefix: "scaledp/sim".into(),
            latched: None,
        }
    }
    /// The seed of the first episode (cubes, targets, the operator's hands) and of the streams'
    /// jitter and latency.
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }
    /// Wall-clock origin of the streams' capture grid (ns since the epoch). With it every
    /// slot of the grid is published, a backlog included (replays, deterministic tests);
    /// without it the streams start now and run in real time, skipping the frames a busy
    /// machine cannot make (with a warning) so that stamps never drift behind real time.
    pub fn start_time_ns(mut self, ns: u64) -> Self {
        self.start_time_ns = Some(ns);
        self
    }
    /// Key style.
    pub fn keys(mut self, keys: KeyStyle) -> Self {
        self.keys = keys;
        self
    }
    /// Bridge namespace prefix (bridge keys only).
    pub fn namespace(mut self, ns: impl Into<String>) -> Self {
        self.namespace = ns.into();
        self
    }
    /// Observe every published message, commands included (tests compare recordings with this).
    pub fn on_publish(mut self, hook: PublishHook) -> Self {
        self.hook = Some(hook);
        self
    }
    /// Render `frames` images per camera up front (the operator's episode, offline) and cycle
    /// through them, so a load test spends its CPU on transport rather than drawing (stamps stay
    /// live; the pictures stop matching the joints).
    pub fn frame_cache(mut self, frames: usize) -> Self {
        self.frame_cache = frames;
        self
    }
    /// Run the scripted operator: it waits for [`Sim::begin`] (or a reset over Zenoh, or
    /// autoplay), then demonstrates the task through the rig's command topics (arms without a
    /// command topic get its commands in-process).
    pub fn scripted_operator(mut self, on: bool) -> Self {
        self.operator = on;
        self
    }
    /// With the operator: demonstrate episode after episode on its own (seed, seed + 1, …;
    /// half a second before each, a second after).
    pub fn autoplay(mut self, on: bool) -> Self {
        self.autoplay = on;
        self
    }
    /// How `/tf_static` is served to late joiners (default: as the key style's peer does it,
    /// the bridge's `@ros2_pub_cache` queryable, rmw_zenoh's AdvancedPublisher cache).
    pub fn latched_cache(mut self, cache: LatchedCache) -> Self {
        self.latched = Some(cache);
        self
    }
    /// Prefix of `<prefix>/reset` and `<prefix>/task`.
    pub fn control_prefix(mut self, prefix: impl Into<String>) -> Self {
        self.control_prefix = prefix.into().trim_matches('/').to_string();
        self
    }

    fn key(&self, topic: &str, message_type: &str) -> String {
        match self.keys {
            KeyStyle::Bridge => bridge_key(&self.namespace, topic),
            KeyStyle::Rmw => rmw_key(0, topic, message_type, "TypeHashNotSupported"),
        }
    }

    /// Starts the world, stream and operator threads and the Zenoh keys on `session`.
    pub fn spawn(self, session: &zenoh::Session) -> Result<Sim> {
        let t0 = self.start_time_ns.unwrap_or_else(now_ns);
        let scene = Arc::new(Scene::new(&self.rig));
        let world = World::with_scene(scene.clone(), self.seed);
        let n_arms = self.rig.arms.len();
        let shared = Arc::new(Shared {
            rig: self.rig.clone(),
            scene: scene.clone(),
            stop: AtomicBool::new(false),
            world: Mutex::new(world),
            operator: Mutex::new(self.operator.then(|| OperatorSlot {
                operator: ScriptedOperator::new(&scene, self.seed),
                begin_at: None,
            })),
            pending: Mutex::new(vec![ArmCommand::default(); n_arms]),
            reset_request: Mutex::new(None),
            reset_wall_ns: AtomicU64::new(now_ns()),
        });
        let zerr = |key: &str| {
            let key = key.to_string();
            move |e: zenoh::Error| Error::Zenoh {
                key: key.clone(),
                reason: e.to_string(),
            }
        };
        let mut subscribers = Vec::new();
        for (i, arm) in self.rig.arms.iter().enumerate() {
            let mut topics = Vec::new();
            if let Some(t) = &arm.command_topic {
                topics.push((
                    t.clone(),
                    arm.command_type.unwrap_or_default().message_type(),
                    false,
                ));
            }
            if let Some(t) = arm.gripper.as_ref().and_then(|g| g.command_topic.clone()) {
                topics.push((t, "sensor_msgs/msg/JointState", true));
            }
            for (topic, message_type, gripper) in topics {
                for key in [
                    bridge_key(&self.namespace, &topic),
                    rmw_key_expr(&topic, message_type),
                ] {
                    let sh = shared.clone();
                    let sub = session
                        .declare_subscriber(key.clone())
                        .callback(move |s: Sample| on_command(&sh, i, gripper, &s))
                        .wait()
                        .map_err(zerr(&key))?;
                    subscribers.push(sub);
                }
            }
        }
        let reset_key = format!("{}/reset", self.control_prefix);
        let sh = shared.clone();
        let sub = session
            .declare_subscriber(reset_key.clone())
            .callback(move |s: Sample| {
                let text = String::from_utf8_lossy(&s.payload().to_bytes())
                    .trim()
                    .to_string();
                let seed = if text.is_empty() {
                    Some(None)
                } else {
                    text.parse().ok().map(Some)
                };
                match seed {
                    Some(seed) => *lock(&sh.reset_request) = Some(seed),
                    None => tracing::warn!("{}: not a seed: {text:?}", s.key_expr()),
                }
            })
            .wait()
            .map_err(zerr(&reset_key))?;
        subscribers.push(sub);
        let status_key = format!("{}/task", self.control_prefix);
        let status = session
            .declare_publisher(status_key.clone())
            .wait()
            .map_err(zerr(&status_key))?;

        let mut threads = Vec::new();
        for (n, stream) in crate::streams::streams(&shared, self.frame_cache, self.seed)?
            .into_iter()
            .enumerate()
        {
            let mut publishers = Vec::new();
            for (topic, message_type) in &stream.outputs {
                let key = self.key(topic, message_type);
                publishers.push(
                    session
                        .declare_publisher(key.clone())
                        .congestion_control(CongestionControl::Block)
                        .wait()
                        .map_err(zerr(&key))?,
                );
            }
            let ctx = crate::streams::StreamCtx {
                shared: shared.clone(),
                hook: self.hook.clone(),
                rng: <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(
                    self.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ n as u64,
                ),
                t0,
                rmw: (self.keys == KeyStyle::Rmw).then(|| vec![n as u8; 16]),
                realtime: self.start_time_ns.is_none(),
            };
            let topic = stream.outputs[0].0.clone();
            let handle = std::thread::Builder::new()
                .name(format!("sim:{topic}"))
                .spawn(move || stream.run(ctx, publishers))
                .map_err(|source| Error::Thread { topic, source })?;
            threads.push(handle);
        }
        let tf_static = self.publish_tf_static(session, &shared, t0)?;
        let mut workers = Vec::new();
        let sh = shared.clone();
        workers.push(
            std::thread::Builder::new()
                .name("sim:world".into())
                .spawn(move || world_loop(&sh, &status))
                .map_err(|source| Error::Thread {
                    topic: "world".into(),
                    source,
                })?,
        );
        if self.operator {
            let mut publishers = Vec::new();
            for arm in &self.rig.arms {
                let declare = |topic: Option<&String>, ty: &str| -> Result<_> {
                    let Some(topic) = topic else { return Ok(None) };
                    let key = self.key(topic, ty);
                    let p = session
                        .declare_publisher(key.clone())
                        .wait()
                        .map_err(zerr(&key))?;
                    Ok(Some((topic.clone(), p)))
                };
                // The scripted operator speaks PoseStamped; a joint-state command topic gets
                // its commands in-process.
                let pose = match arm.command_type.unwrap_or_default() {
                    CommandType::PoseStamped => {
                        declare(arm.command_topic.as_ref(), "geometry_msgs/msg/PoseStamped")?
                    }
                    CommandType::JointState => None,
                };
                let grip = declare(
                    arm.gripper.as_ref().and_then(|g| g.command_topic.as_ref()),
                    "sensor_msgs/msg/JointState",
                )?;
                publishers.push((pose, grip));
            }
            let sh = shared.clone();
            let hook = self.hook.clone();
            let autoplay = self.autoplay.then_some(self.seed);
            workers.push(
                std::thread::Builder::new()
                    .name("sim:operator".into())
                    .spawn(move || operator_loop(&sh, &publishers, hook.as_ref(), autoplay))
                    .map_err(|source| Error::Thread {
                        topic: "operator".into(),
                        source,
                    })?,
            );
        }
        Ok(Sim {
            shared,
            threads,
            workers,
            _subscribers: subscribers,
            _tf_static: tf_static,
        })
    }

    /// Publishes the rig's `/tf_static` once, stamped `t0`, on a publisher that serves it to
    /// late joiners as the key style's peer does; kept alive with the simulation.
    fn publish_tf_static(
        &self,
        session: &zenoh::Session,
        shared: &Shared,
        t0: u64,
    ) -> Result<Option<Box<LatchedPublisher>>> {
        let Some(tf) = self.rig.tf.as_ref().filter(|t| t.static_) else {
            return Ok(None);
        };
        let cache = self.latched.unwrap_or(match self.keys {
            KeyStyle::Bridge => LatchedCache::BridgeQueryable,
            KeyStyle::Rmw => LatchedCache::Advanced,
        });
        let key = self.key(&tf.static_topic, scaledp_schema::rig::TF_MESSAGE);
        let publisher = LatchedPublisher::declare(session, &key, cache)?;
        let views: Vec<View> = self
            .rig
            .cameras
            .iter()
            .enumerate()
            .map(|(i, c)| View::for_camera(&shared.scene, c, i))
            .collect();
        let payload = crate::tf::tf_static(&self.rig, &shared.scene, &views, t0).to_cdr();
        if let Some(h) = &self.hook {
            h(&tf.static_topic, &payload);
        }
        let attachment = (self.keys == KeyStyle::Rmw).then(|| {
            RmwAttachment {
                sequence_number: 1,
                source_timestamp_ns: now_ns() as i64,
                source_gid: vec![0xF5; 16],
            }
            .to_zbytes()
        });
        publisher.publish(payload, attachment);
        Ok(Some(Box::new(publisher)))
    }
}

/// A running simulation.
pub struct Sim {
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<Vec<(String, u64)>>>,
    workers: Vec<JoinHandle<()>>,
    _subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
    /// Boxed: an AdvancedPublisher is large, and a `Sim` is held by value.
    _tf_static: Option<Box<LatchedPublisher>>,
}

impl Sim {
    /// Resets the world (and the operator, who then waits) to `seed` now.
    pub fn reset(&self, seed: u64) {
        self.shared.reset(seed);
    }

    /// The operator starts demonstrating now (nothing without an operator).
    pub fn begin(&self) {
        if let Some(slot) = lock(&self.shared.operator).as_mut() {
            slot.begin_at = Some(Instant::now());
        }
    }

    /// The task's privileged state now.
    pub fn task(&self) -> TaskState {
        lock(&self.shared.world).task_state()
    }

    /// The whole world now.
    pub fn state(&self) -> WorldState {
        self.shared.state()
    }

    /// The fixed geometry.
    pub fn scene(&self) -> &Arc<Scene> {
        &self.shared.scene
    }

    /// True when the operator has finished its demonstration.
    pub fn operator_done(&self) -> bool {
        lock(&self.shared.operator)
            .as_ref()
            .is_some_and(|s| s.operator.done())
    }

    /// One operator episode: reset to `seed`, wait `settle_s` (so every stream carries the new
    /// scene), call `on_start` (start a recording), let the operator demonstrate until it is done,
    /// `max_s` pass or `stop` is set, and report the task as it then is. Without an operator it
    /// just waits `max_s`.
    pub fn run_episode(
        &self,
        seed: u64,
        settle_s: f64,
        max_s: f64,
        on_start: &mut dyn FnMut(),
        stop: &AtomicBool,
    ) -> EpisodeResult {
        self.reset(seed);
        std::thread::sleep(Duration::from_secs_f64(settle_s));
        on_start();
        self.begin();
        let start = Instant::now();
        while !self.operator_done()
            && start.elapsed().as_secs_f64() < max_s
            && !stop.load(Ordering::Relaxed)
        {
            std::thread::sleep(Duration::from_millis(10));
        }
        EpisodeResult {
            task: self.task(),
            operator_done: self.operator_done(),
            duration_s: start.elapsed().as_secs_f64(),
        }
    }

    /// Stops every thread and returns (topic, messages published) per measurement topic, in
    /// the streams' order (cameras with what they publish beside colour, arms, grippers, /tf).
    pub fn stop(mut self) -> Vec<(String, u64)> {
        self.shared.stop.store(true, Ordering::Relaxed);
        for w in std::mem::take(&mut self.workers) {
            let _ = w.join();
        }
        std::mem::take(&mut self.threads)
            .into_iter()
            .filter_map(|h| h.join().ok())
            .flatten()
            .collect()
    }
}

impl Drop for Sim {
    /// Tells every thread to stop (without waiting for them).
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
    }
}
