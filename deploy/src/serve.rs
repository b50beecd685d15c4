//! `scaledp serve`: the [`Controller`] on Zenoh. Subscribes to the rig's cameras (those the
//! checkpoint reads), joint states and gripper states under the recorder's keys
//! (zenoh-bridge-ros2dds: the topic without its leading `/`; rmw_zenoh:
//! `<domain>/<topic>/<type>/<hash>`), ticks at the checkpoint's control rate on the wall clock,
//! runs inference on its own thread (the next chunk is computed while the current one is
//! executed: the controller asks for it `lead` ticks early, `lead` being the measured median
//! latency in ticks), and publishes per arm a `geometry_msgs/msg/PoseStamped` TCP target on the
//! arm's `command_topic` and a `sensor_msgs/msg/JointState` gripper target on the gripper's
//! `command_topic`, as the simulator and the scripted teleoperator speak them.
//!
//! Header stamps and the tick are compared on one clock: the rig's clocks must be synchronized
//! with this machine's (PTP / chrony), as they must be for recording.
//!
//! A JSON [`Status`] goes out once a second on the status key (default `scaledp/serve/status`).

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use scaledp_policy::{ActionChunk, Policy};
use scaledp_recorder::keys::{bridge_key, rmw_key, rmw_key_expr, RmwAttachment};
use scaledp_recorder::now_ns;
use scaledp_schema::msg::{CompressedImage, Image, JointState};
use scaledp_schema::{Rig, RosMessage};
use scaledp_sim::{messages, KeyStyle};
use serde::Serialize;
use zenoh::sample::Sample;
use zenoh::Wait;

use crate::controller::{Command, ControlOptions, Controller, Request};
use crate::error::{Error, Result};
use crate::stats::percentile;

/// Called with the tick index and the commands of every tick that has some.
pub type CommandHook = Arc<dyn Fn(u64, &[Command]) + Send + Sync>;

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
        }
    }
}

/// What a serving node is doing (its status key's JSON).
#[derive(Debug, Clone, Default, Serialize)]
pub struct Status {
    /// Control ticks so far.
    pub ticks: u64,
    /// Ticks with commands (published, or printed with `--dry-run`).
    pub commanded_ticks: u64,
    /// Ticks with a clamped command.
    pub clamped_ticks: u64,
    /// Ticks stopped on stale or missing observations.
    pub halted_ticks: u64,
    /// Chunks predicted.
    pub chunks: u64,
    /// Commanded ticks per second over the last two seconds.
    pub command_rate_hz: f64,
    /// Inference latency (ms): median and 99th percentile.
    pub inference_ms_p50: Option<f64>,
    /// See `inference_ms_p50`.
    pub inference_ms_p99: Option<f64>,
    /// End-to-end latency (ms): from the newest camera frame received when a window was taken
    /// to the first command published from that window's chunk; median and 99th percentile.
    pub e2e_ms_p50: Option<f64>,
    /// See `e2e_ms_p50`.
    pub e2e_ms_p99: Option<f64>,
    /// Why the last tick had no command, if it had none.
    pub holding: Option<String>,
    /// Nothing is published.
    pub dry_run: bool,
}

impl Status {
    /// The one-line form.
    pub fn line(&self) -> String {
        let ms = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.0}"));
        format!(
            "{:.1} cmd/s, inference p50 {} ms p99 {} ms, frame→command p50 {} ms, {} chunks, {} ticks ({} clamped, {} halted){}{}",
            self.command_rate_hz,
            ms(self.inference_ms_p50),
            ms(self.inference_ms_p99),
            ms(self.e2e_ms_p50),
            self.chunks,
            self.ticks,
            self.clamped_ticks,
            self.halted_ticks,
            if self.dry_run { ", dry run" } else { "" },
            self.holding.as_ref().map_or(String::new(), |h| format!(" — holding: {h}"))
        )
    }
}

enum Input {
    Image(usize, u64, u64, Vec<u8>),
    Joints(usize, bool, u64, JointState),
}

/// A running node.
pub struct Server {
    stop: Arc<AtomicBool>,
    status: Arc<Mutex<Status>>,
    threads: Vec<JoinHandle<()>>,
    _subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

struct Outputs {
    /// Per arm: pose publisher and key type, gripper publisher.
    arms: Vec<(
        Option<zenoh::pubsub::Publisher<'static>>,
        Option<zenoh::pubsub::Publisher<'static>>,
    )>,
    rmw: bool,
    seq: i64,
    status: zenoh::pubsub::Publisher<'static>,
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
        for &c in ctl.cameras() {
            let cam = &rig.cameras[c];
            let (k, ty, tx) = (
                sub_key(&cam.topic, cam.message_type()),
                cam.message_type(),
                tx.clone(),
            );
            let compressed = ty.ends_with("CompressedImage");
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
                        let _ = tx.send(Input::Image(c, stamp, now_ns(), data));
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
                let sub = session
                    .declare_subscriber(k.clone())
                    .callback(move |s: Sample| {
                        if let Ok(js) = JointState::from_cdr(&s.payload().to_bytes()) {
                            let _ = tx.send(Input::Joints(a, gripper, now_ns(), js));
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
                .map(|t| declare(key(t, "geometry_msgs/msg/PoseStamped")))
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
            Box::new(move || control_loop(ctl, rx, req_tx, res_rx, outputs, hook, &st, &sp)),
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

#[allow(clippy::too_many_arguments)]
fn control_loop(
    mut ctl: Controller,
    rx: Receiver<Input>,
    req_tx: Sender<Request>,
    res_rx: Receiver<(u64, ActionChunk, f64)>,
    mut out: Outputs,
    hook: Option<CommandHook>,
    status: &Mutex<Status>,
    stop: &AtomicBool,
) {
    let period = Duration::from_nanos(ctl.period_ns());
    let mut next = Instant::now() + period;
    let mut latencies: VecDeque<f64> = VecDeque::new();
    let mut commanded: VecDeque<Instant> = VecDeque::new();
    // Receive time of the newest frame behind each request, and of the chunk just installed.
    let mut frame_of_request: VecDeque<(u64, u64)> = VecDeque::new();
    let mut fresh_chunk: Option<u64> = None;
    let mut e2e: VecDeque<f64> = VecDeque::new();
    let started = Instant::now();
    let mut last_status = Instant::now();
    let mut st = Status {
        dry_run: lock(status).dry_run,
        ..Status::default()
    };
    while !stop.load(Ordering::Relaxed) {
        match rx.recv_timeout(next.saturating_duration_since(Instant::now())) {
            Ok(Input::Image(c, stamp, recv, data)) => {
                let ty = ctl.rig().cameras[c].message_type();
                ctl.on_image(c, stamp, recv, ty, data);
                continue;
            }
            Ok(Input::Joints(a, g, recv, js)) => {
                ctl.on_joint_state(a, g, recv, &js);
                continue;
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
        let now = Instant::now();
        next += period;
        if next < now {
            next = now + period; // fell behind: skip ticks rather than bunch them
        }
        for (index, chunk, ms) in res_rx.try_iter() {
            ctl.install(index, &chunk);
            while let Some(&(i, frame_ns)) = frame_of_request.front() {
                frame_of_request.pop_front();
                if i == index {
                    fresh_chunk = Some(frame_ns);
                    break;
                }
            }
            st.chunks += 1;
            latencies.push_back(ms);
            if latencies.len() > 200 {
                latencies.pop_front();
            }
            let v: Vec<f64> = latencies.iter().copied().collect();
            st.inference_ms_p50 = percentile(&v, 0.5);
            st.inference_ms_p99 = percentile(&v, 0.99);
            let p50_ns = st.inference_ms_p50.unwrap_or(0.0) * 1e6;
            ctl.set_lead_ticks((p50_ns / ctl.period_ns() as f64).ceil() as u64);
        }
        let tick = ctl.tick(now_ns());
        st.ticks += 1;
        st.halted_ticks += u64::from(tick.halted.is_some());
        if let Some(req) = tick.request {
            if let Some(f) = ctl.newest_frame_ns() {
                frame_of_request.push_back((req.index, f));
            }
            let _ = req_tx.send(req);
        }
        match ctl.command() {
            Ok(cmds) => {
                st.holding = None;
                st.commanded_ticks += 1;
                st.clamped_ticks += u64::from(cmds.iter().any(|c| c.clamped.any()));
                commanded.push_back(now);
                publish(&ctl, &mut out, &cmds);
                if let Some(f) = fresh_chunk.take() {
                    e2e.push_back(now_ns().saturating_sub(f) as f64 * 1e-6);
                    if e2e.len() > 200 {
                        e2e.pop_front();
                    }
                    let v: Vec<f64> = e2e.iter().copied().collect();
                    st.e2e_ms_p50 = percentile(&v, 0.5);
                    st.e2e_ms_p99 = percentile(&v, 0.99);
                }
                if let Some(h) = &hook {
                    h(tick.index, &cmds);
                }
            }
            Err(why) => st.holding = Some(why),
        }
        while commanded
            .front()
            .is_some_and(|t| now.duration_since(*t) > Duration::from_secs(2))
        {
            commanded.pop_front();
        }
        let window = started.elapsed().as_secs_f64().clamp(1e-3, 2.0);
        st.command_rate_hz = commanded.len() as f64 / window;
        *lock(status) = st.clone();
        if last_status.elapsed() >= Duration::from_secs(1) {
            last_status = Instant::now();
            if let Ok(json) = serde_json::to_string(&st) {
                let _ = out.status.put(json).wait();
            }
        }
    }
}

fn publish(ctl: &Controller, out: &mut Outputs, cmds: &[Command]) {
    let stamp = now_ns();
    for c in cmds {
        let arm = &ctl.rig().arms[c.arm];
        let Some((pose_pub, grip_pub)) = out.arms.get(c.arm) else {
            continue;
        };
        let mut put = |p: &zenoh::pubsub::Publisher<'static>, bytes: Vec<u8>| {
            out.seq += 1;
            let put = p.put(bytes);
            let r = if out.rmw {
                put.attachment(
                    RmwAttachment {
                        sequence_number: out.seq,
                        source_timestamp_ns: stamp as i64,
                        source_gid: vec![0x5e; 16],
                    }
                    .to_zbytes(),
                )
                .wait()
            } else {
                put.wait()
            };
            if let Err(e) = r {
                tracing::warn!("{}: {e}", p.key_expr());
            }
        };
        if let Some(p) = pose_pub {
            put(
                p,
                messages::pose_command(arm, &c.base_from_tcp, stamp).to_cdr(),
            );
        }
        if let (Some(p), Some(g), Some(w)) = (grip_pub, &arm.gripper, c.gripper_width_m) {
            put(p, messages::gripper_command(g, w, stamp).to_cdr());
        }
    }
}
