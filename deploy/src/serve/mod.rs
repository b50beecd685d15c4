//! `scaledp serve`: the [`Controller`] on Zenoh. Subscribes to the rig's cameras (those the
//! checkpoint reads), joint states and gripper states under the recorder's keys
//! (zenoh-bridge-ros2dds: the topic without its leading `/`; rmw_zenoh:
//! `<domain>/<topic>/<type>/<hash>`), ticks at the checkpoint's control rate on the wall clock,
//! runs inference on its own thread (the next chunk is computed while the current one is
//! executed: the controller asks for it `lead` ticks early, `lead` being the measured median
//! latency in ticks), and publishes per arm what its `command_topic` takes (a
//! `geometry_msgs/msg/PoseStamped` TCP target, or a leader arm's `sensor_msgs/msg/JointState`
//! of joint targets, whichever space the checkpoint acts in) and a `sensor_msgs/msg/JointState`
//! gripper target on the gripper's `command_topic`, as the simulators and the scripted
//! teleoperator speak them.
//!
//! Header stamps and the tick are compared on one clock: the rig's clocks must be synchronized
//! with this machine's (PTP / chrony), as they must be for recording.
//!
//! A JSON [`Status`] goes out once a second on the status key (default `scaledp/serve/status`).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;

use scaledp_policy::{ActionChunk, Policy};
use scaledp_recorder::keys::{bridge_key, rmw_key, rmw_key_expr};
use scaledp_schema::msg::{Clock, CompressedImage, Image, JointState};
use scaledp_schema::{Rig, RosMessage};
use scaledp_sim::KeyStyle;

use zenoh::sample::Sample;
use zenoh::Wait;

use crate::controller::{ControlOptions, Controller, Request};
use crate::error::{Error, Result};

mod control;
mod shared;

use control::{control_loop, Clocks, Outputs};
use shared::{lock, Input};
pub use shared::{CommandHook, Status};

/// Settings of a serving node.
#[derive(Clone)]
pub struct ServeOptions {
    /// The rig driven.
    pub rig: Rig,
    /// Key style of its topics.
    pub keys: KeyStyle,
    /// Bridge namespace (bridge keys only).
    pub namespace: String,
    /// The controller's settings.
    pub control: ControlOptions,
    /// Publish nothing (the hook still sees every command).
    pub dry_run: bool,
    /// Where the JSON status goes.
    pub status_key: String,
    /// Seed of the sampling noise (chunk k uses seed + k).
    pub seed: u64,
    /// Sees every tick's commands.
    pub on_commands: Option<CommandHook>,
    /// Follow a simulation's `rosgraph_msgs/msg/Clock` topic (ROS's `use_sim_time`, e.g.
    /// `/clock`) instead of the wall clock: ticks, receive times and command stamps are its
    /// time, so a simulator slower than real time is served as a robot would be.
    pub clock: Option<String>,
}

impl ServeOptions {
    /// Bridge keys, default control, publishing, status on `scaledp/serve/status`.
    pub fn new(rig: Rig) -> Self {
        ServeOptions {
            rig,
            keys: KeyStyle::Bridge,
            namespace: String::new(),
            control: ControlOptions::default(),
            dry_run: false,
            status_key: "scaledp/serve/status".into(),
            seed: 0,
            on_commands: None,
            clock: None,
        }
    }
}

/// A running node.
pub struct Server {
    stop: Arc<AtomicBool>,
    status: Arc<Mutex<Status>>,
    threads: Vec<JoinHandle<()>>,
    _subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
}

impl Server {
    /// Checks `policy` against the rig (one-line error before anything is declared), then
    /// starts the subscribers, the control thread and the inference thread on `session`.
    pub fn start(policy: Policy, opts: ServeOptions, session: &zenoh::Session) -> Result<Server> {
        let ckpt = policy.dir().display().to_string();
        let ctl = Controller::new(policy.config(), &ckpt, &opts.rig, opts.control.clone())?;
        let rig = opts.rig.clone();
        let key = |topic: &str, ty: &str| match opts.keys {
            KeyStyle::Bridge => bridge_key(&opts.namespace, topic),
            KeyStyle::Rmw => rmw_key(0, topic, ty, "TypeHashNotSupported"),
        };
        let sub_key = |topic: &str, ty: &str| match opts.keys {
            KeyStyle::Bridge => bridge_key(&opts.namespace, topic),
            KeyStyle::Rmw => rmw_key_expr(topic, ty),
        };
        let (tx, rx) = crossbeam_channel::unbounded::<Input>();
        let mut subscribers = Vec::new();
        let clocks = Clocks {
            sim: opts
                .clock
                .as_ref()
                .map(|_| Arc::new(std::sync::atomic::AtomicU64::new(0))),
        };
        if let (Some(topic), Some(now)) = (&opts.clock, &clocks.sim) {
            let (k, tx, now) = (
                sub_key(topic, "rosgraph_msgs/msg/Clock"),
                tx.clone(),
                now.clone(),
            );
            let sub = session
                .declare_subscriber(k.clone())
                .callback(move |s: Sample| {
                    if let Ok(c) = Clock::from_cdr(&s.payload().to_bytes()) {
                        let ns = c.clock.as_ns();
                        now.store(ns, Ordering::Relaxed);
                        let _ = tx.send(Input::Clock(ns));
                    }
                })
                .wait()
                .map_err(|e| Error::zenoh(&k, e))?;
            subscribers.push(sub);
        }
        for &c in ctl.cameras() {
            let cam = &rig.cameras[c];
            let (k, ty, tx) = (
                sub_key(&cam.topic, cam.message_type()),
                cam.message_type(),
                tx.clone(),
            );
            let compressed = ty.ends_with("CompressedImage");
            let clk = clocks.clone();
            let sub = session
                .declare_subscriber(k.clone())
                .callback(move |s: Sample| {
                    let data = s.payload().to_bytes().to_vec();
                    let stamp = if compressed {
                        CompressedImage::from_cdr(&data).map(|m| m.header.stamp.as_ns())
                    } else {
                        Image::from_cdr(&data).map(|m| m.header.stamp.as_ns())
                    };
                    if let Ok(stamp) = stamp {
                        let _ = tx.send(Input::Image(c, stamp, clk.now_ns(), data));
                    }
                })
                .wait()
                .map_err(|e| Error::zenoh(&k, e))?;
            subscribers.push(sub);
        }
        for (a, arm) in rig.arms.iter().enumerate() {
            let mut topics = vec![(arm.joint_state_topic.clone(), false)];
            if let Some(g) = &arm.gripper {
                topics.push((g.topic.clone(), true));
            }
            for (topic, gripper) in topics {
                let (k, tx) = (sub_key(&topic, "sensor_msgs/msg/JointState"), tx.clone());
                let clk = clocks.clone();
                let sub = session
                    .declare_subscriber(k.clone())
                    .callback(move |s: Sample| {
                        if let Ok(js) = JointState::from_cdr(&s.payload().to_bytes()) {
                            let _ = tx.send(Input::Joints(a, gripper, clk.now_ns(), js));
                        }
                    })
                    .wait()
                    .map_err(|e| Error::zenoh(&k, e))?;
                subscribers.push(sub);
            }
        }
        let declare = |k: String| -> Result<zenoh::pubsub::Publisher<'static>> {
            session
                .declare_publisher(k.clone())
                .wait()
                .map_err(|e| Error::zenoh(&k, e))
        };
        let mut arms = Vec::new();
        for arm in &rig.arms {
            if opts.dry_run {
                arms.push((None, None));
                continue;
            }
            let pose = arm
                .command_topic
                .as_ref()
                .map(|t| declare(key(t, arm.command_type.unwrap_or_default().message_type())))
                .transpose()?;
            let grip = arm
                .gripper
                .as_ref()
                .and_then(|g| g.command_topic.as_ref())
                .map(|t| declare(key(t, "sensor_msgs/msg/JointState")))
                .transpose()?;
            arms.push((pose, grip));
        }
        let outputs = Outputs {
            arms,
            rmw: opts.keys == KeyStyle::Rmw,
            seq: 0,
            status: declare(opts.status_key.clone())?,
        };
        let stop = Arc::new(AtomicBool::new(false));
        let status = Arc::new(Mutex::new(Status {
            dry_run: opts.dry_run,
            ..Status::default()
        }));
        let (req_tx, req_rx) = crossbeam_channel::unbounded::<Request>();
        let (res_tx, res_rx) = crossbeam_channel::unbounded::<(u64, ActionChunk, f64)>();
        let seed = opts.seed;
        let spawn = |name: &str, f: Box<dyn FnOnce() + Send>| {
            std::thread::Builder::new()
                .name(name.into())
                .spawn(f)
                .map_err(|source| Error::Thread {
                    name: name.into(),
                    source,
                })
        };
        let inference = spawn(
            "serve:inference",
            Box::new(move || {
                for (k, req) in req_rx.iter().enumerate() {
                    let t = Instant::now();
                    match policy.predict(&req.observation, seed.wrapping_add(k as u64)) {
                        Ok(chunk) => {
                            let ms = t.elapsed().as_secs_f64() * 1e3;
                            if res_tx.send((req.index, chunk, ms)).is_err() {
                                break;
                            }
                        }
                        Err(e) => tracing::error!("inference: {e}"),
                    }
                }
            }),
        )?;
        let (st, sp) = (status.clone(), stop.clone());
        let hook = opts.on_commands.clone();
        let control = spawn(
            "serve:control",
            Box::new(move || {
                control_loop(ctl, rx, req_tx, res_rx, outputs, hook, clocks, &st, &sp)
            }),
        )?;
        Ok(Server {
            stop,
            status,
            threads: vec![control, inference],
            _subscribers: subscribers,
        })
    }

    /// The status now.
    pub fn status(&self) -> Status {
        lock(&self.status).clone()
    }

    /// Stops the threads and returns the final status.
    pub fn stop(mut self) -> Status {
        self.stop.store(true, Ordering::Relaxed);
        for t in std::mem::take(&mut self.threads) {
            let _ = t.join();
        }
        self.status()
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}
