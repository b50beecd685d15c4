//! The simulated rig, the stand-in for a real robot cell in demos, tests and benchmarks.
//!
//! [`SimOptions`] → [`SimOptions::spawn`] → [`Sim`] → [`Sim::stop`] publishes a rig's cameras and joint states over Zenoh exactly as
//! zenoh-bridge-ros2dds does (key = topic without its leading `/`, payload = CDR with its
//! encapsulation header), or as rmw_zenoh does (domain/topic/type/hash keys with attachments).
//!
//! Each stream runs on its own thread at the rig's rate. `header.stamp` is the capture time; the
//! message leaves later by a realistic latency (cameras tens of ms, arms well under one ms), and
//! both carry seeded jitter. Everything but the wall-clock origin is fixed by the seed; fix that
//! too with [`SimOptions::start_time_ns`].

mod error;
pub mod render;
pub mod scene;
pub mod synth;

pub use error::{Error, Result};
pub use synth::write_episode;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scaledp_recorder::keys::{bridge_key, rmw_key, RmwAttachment};
use scaledp_recorder::now_ns;
use scaledp_schema::msg::{Header, Image, JointState, Time};
use scaledp_schema::rig::Rig;
use scaledp_schema::RosMessage;
use zenoh::qos::CongestionControl;
use zenoh::Wait;

use render::View;
use scene::Scene;

/// Called with (topic, payload) for every message just before it is published.
pub type PublishHook = Arc<dyn Fn(&str, &[u8]) + Send + Sync>;

/// How topics map to Zenoh keys.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum KeyStyle {
    /// zenoh-bridge-ros2dds: `zed/zed_node/...`, no attachment.
    #[default]
    Bridge,
    /// rmw_zenoh (Humble): `0/<topic>/<pkg::msg::dds_::T_>/TypeHashNotSupported` with attachments.
    Rmw,
}

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
}

impl SimOptions {
    /// Simulates `rig` with seed 0, bridge keys, starting now.
    pub fn new(rig: Rig) -> Self {
        Self {
            rig,
            seed: 0,
            start_time_ns: None,
            keys: KeyStyle::Bridge,
            namespace: String::new(),
            hook: None,
            frame_cache: 0,
        }
    }
    /// The seed fixing trajectories, jitter and latency.
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }
    /// Wall-clock origin of the simulation (ns since the epoch); messages are due from then on.
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
    /// Observe every published message (tests compare recordings with this).
    pub fn on_publish(mut self, hook: PublishHook) -> Self {
        self.hook = Some(hook);
        self
    }

    /// Render `frames` images per camera up front and cycle through them, so a load test spends
    /// its CPU on transport rather than drawing (stamps stay live; the scene stops matching).
    pub fn frame_cache(mut self, frames: usize) -> Self {
        self.frame_cache = frames;
        self
    }

    /// Starts one publishing thread per stream on `session`.
    pub fn spawn(self, session: &zenoh::Session) -> Result<Sim> {
        let t0 = self.start_time_ns.unwrap_or_else(now_ns);
        let scene = Arc::new(Scene::new(&self.rig, self.seed));
        let table_z = render::table_height(&scene);
        let stop = Arc::new(AtomicBool::new(false));
        let mut threads = Vec::new();
        let mut streams: Vec<Stream> = Vec::new();
        for (i, cam) in self.rig.cameras.iter().enumerate() {
            let view = View::for_camera(&scene, cam, i);
            let cache = (0..self.frame_cache)
                .map(|k| {
                    let mut buf = Vec::new();
                    let state = scene.state_at(k as f64 / cam.fps);
                    render::render(&scene, &view, &state, cam.encoding(), table_z, &mut buf);
                    buf
                })
                .collect();
            let latency_ms = if cam.model == scaledp_schema::rig::CameraModel::Zed {
                30.0
            } else {
                15.0
            };
            streams.push(Stream {
                topic: cam.topic.clone(),
                message_type: "sensor_msgs/msg/Image",
                rate_hz: cam.fps,
                latency_ms: (latency_ms, 8.0),
                stamp_jitter_ms: 0.5,
                kind: Kind::Camera {
                    view,
                    cam: cam.clone(),
                    table_z,
                    cache,
                },
            });
        }
        for (i, arm) in self.rig.arms.iter().enumerate() {
            streams.push(Stream {
                topic: arm.joint_state_topic.clone(),
                message_type: "sensor_msgs/msg/JointState",
                rate_hz: arm.rate_hz,
                latency_ms: (0.3, 0.4),
                stamp_jitter_ms: 0.02,
                kind: Kind::Arm {
                    index: i,
                    names: arm.joint_names.clone(),
                },
            });
            if let Some(g) = &arm.gripper {
                streams.push(Stream {
                    topic: g.topic.clone(),
                    message_type: "sensor_msgs/msg/JointState",
                    rate_hz: g.rate_hz,
                    latency_ms: (2.0, 2.0),
                    stamp_jitter_ms: 0.5,
                    kind: Kind::Gripper {
                        index: i,
                        model: g.model,
                        names: g.joint_names.clone(),
                    },
                });
            }
        }
        for (n, stream) in streams.into_iter().enumerate() {
            let key = match self.keys {
                KeyStyle::Bridge => bridge_key(&self.namespace, &stream.topic),
                KeyStyle::Rmw => rmw_key(
                    0,
                    &stream.topic,
                    stream.message_type,
                    "TypeHashNotSupported",
                ),
            };
            let publisher = session
                .declare_publisher(key.clone())
                .congestion_control(CongestionControl::Block)
                .wait()
                .map_err(|e| Error::Zenoh {
                    key: key.clone(),
                    reason: e.to_string(),
                })?;
            let ctx = StreamCtx {
                scene: scene.clone(),
                stop: stop.clone(),
                hook: self.hook.clone(),
                rng: ChaCha8Rng::seed_from_u64(
                    self.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ n as u64,
                ),
                t0,
                rmw: (self.keys == KeyStyle::Rmw).then(|| vec![n as u8; 16]),
            };
            let topic = stream.topic.clone();
            let handle = std::thread::Builder::new()
                .name(format!("sim:{topic}"))
                .spawn(move || stream.run(ctx, publisher))
                .map_err(|source| Error::Thread { topic, source })?;
            threads.push(handle);
        }
        Ok(Sim { stop, threads })
    }
}

/// A running simulation.
pub struct Sim {
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<(String, u64)>>,
}

impl Sim {
    /// Stops every stream and returns (topic, messages published) in rig order.
    pub fn stop(self) -> Vec<(String, u64)> {
        self.stop.store(true, Ordering::Relaxed);
        self.threads
            .into_iter()
            .filter_map(|h| h.join().ok())
            .collect()
    }
}

// One value per stream thread: the size difference between variants costs nothing.
#[allow(clippy::large_enum_variant)]
enum Kind {
    Camera {
        view: View,
        cam: scaledp_schema::rig::Camera,
        table_z: f64,
        cache: Vec<Vec<u8>>,
    },
    Arm {
        index: usize,
        names: Vec<String>,
    },
    Gripper {
        index: usize,
        model: scaledp_schema::rig::GripperModel,
        names: Vec<String>,
    },
}

struct Stream {
    topic: String,
    message_type: &'static str,
    rate_hz: f64,
    /// Base latency and the width of its uniform jitter (ms).
    latency_ms: (f64, f64),
    /// Half-width of the uniform jitter of capture times (ms).
    stamp_jitter_ms: f64,
    kind: Kind,
}

struct StreamCtx {
    scene: Arc<Scene>,
    stop: Arc<AtomicBool>,
    hook: Option<PublishHook>,
    rng: ChaCha8Rng,
    t0: u64,
    rmw: Option<Vec<u8>>,
}

impl Stream {
    fn run(
        self,
        mut ctx: StreamCtx,
        publisher: zenoh::pubsub::Publisher<'static>,
    ) -> (String, u64) {
        let period_ns = 1e9 / self.rate_hz;
        let mut image_buf = Vec::new();
        let mut k: u64 = 0;
        while !ctx.stop.load(Ordering::Relaxed) {
            let jitter = ctx.rng.random_range(-1.0..=1.0) * self.stamp_jitter_ms * 1e6;
            let latency =
                (self.latency_ms.0 + ctx.rng.random_range(0.0..=1.0) * self.latency_ms.1) * 1e6;
            let capture_ns = ctx.t0 + (k as f64 * period_ns + jitter).max(0.0) as u64;
            let t_s = (capture_ns - ctx.t0) as f64 * 1e-9;
            let payload = self.message(&ctx.scene, k, t_s, capture_ns, &mut image_buf);
            let due = capture_ns + latency as u64;
            let now = now_ns();
            if due > now {
                std::thread::sleep(Duration::from_nanos(due - now));
            }
            if ctx.stop.load(Ordering::Relaxed) {
                break;
            }
            if let Some(hook) = &ctx.hook {
                hook(&self.topic, &payload);
            }
            let put = publisher.put(payload);
            let put = match &ctx.rmw {
                Some(gid) => put.attachment(
                    RmwAttachment {
                        sequence_number: k as i64 + 1,
                        source_timestamp_ns: now_ns() as i64,
                        source_gid: gid.clone(),
                    }
                    .to_zbytes(),
                ),
                None => put,
            };
            if let Err(e) = put.wait() {
                tracing::warn!("{}: {e}", self.topic);
            }
            k += 1;
        }
        (self.topic, k)
    }

    fn message(
        &self,
        scene: &Scene,
        k: u64,
        t_s: f64,
        capture_ns: u64,
        image_buf: &mut Vec<u8>,
    ) -> Vec<u8> {
        let stamp = Time::from_ns(capture_ns);
        match &self.kind {
            Kind::Camera {
                view,
                cam,
                table_z,
                cache,
            } => {
                if cache.is_empty() {
                    let state = scene.state_at(t_s);
                    render::render(scene, view, &state, cam.encoding(), *table_z, image_buf);
                } else {
                    image_buf.clear();
                    image_buf.extend_from_slice(&cache[k as usize % cache.len()]);
                }
                let channels = render::layout(cam.encoding()).map_or(3, |l| l.0) as u32;
                let image = Image {
                    header: Header {
                        stamp,
                        frame_id: format!("{}_camera_optical_frame", cam.name),
                    },
                    height: cam.height,
                    width: cam.width,
                    encoding: cam.encoding().to_string(),
                    is_bigendian: 0,
                    step: cam.width * channels,
                    data: std::mem::take(image_buf),
                };
                let out = image.to_cdr();
                *image_buf = image.data; // reuse the pixel buffer for the next frame
                out
            }
            Kind::Arm { index, names } => {
                let q = &scene.state_at(t_s).arms[*index].q;
                let (a, b) = (scene.state_at(t_s - 5e-4), scene.state_at(t_s + 5e-4));
                let velocity = a.arms[*index]
                    .q
                    .iter()
                    .zip(&b.arms[*index].q)
                    .map(|(x, y)| (y - x) / 1e-3)
                    .collect();
                JointState {
                    header: Header {
                        stamp,
                        frame_id: String::new(),
                    },
                    name: names.clone(),
                    position: q.clone(),
                    velocity,
                    effort: vec![0.0; q.len()],
                }
                .to_cdr()
            }
            Kind::Gripper {
                index,
                model,
                names,
            } => {
                let width = scene.state_at(t_s).arms[*index].gripper_width_m;
                JointState {
                    header: Header {
                        stamp,
                        frame_id: String::new(),
                    },
                    name: names.clone(),
                    position: model.positions_for_width(width, names.len()),
                    velocity: vec![0.0; names.len()],
                    effort: vec![0.0; names.len()],
                }
                .to_cdr()
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;
    use std::sync::Mutex;
    use std::time::Instant;

    use scaledp_recorder::net;
    use scaledp_schema::msg::header_stamp;

    use super::*;

    /// An origin long past: every message is due at once, so the streams run flat out and the
    /// run's timing cannot shape what they publish.
    const T0: u64 = 1_700_000_000_000_000_000;
    const N: usize = 40;

    fn small_rig() -> Rig {
        let mut rig = Rig::builtin("franka_2zed").unwrap();
        for c in &mut rig.cameras {
            c.width = 32;
            c.height = 24;
        }
        rig
    }

    /// The first `N` messages of every topic the live simulator publishes under `seed` (on a
    /// session that only listens on a free loopback port, so nothing else receives them).
    fn first_messages(rig: &Rig, seed: u64) -> BTreeMap<String, Vec<Vec<u8>>> {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .unwrap()
            .port();
        let listen = [format!("tcp/127.0.0.1:{port}")];
        let session = net::open(net::zenoh_config(None, &[], &listen).unwrap()).unwrap();
        let got: Arc<Mutex<BTreeMap<String, Vec<Vec<u8>>>>> = Arc::default();
        let sink = got.clone();
        let sim = SimOptions::new(rig.clone())
            .seed(seed)
            .start_time_ns(T0)
            .on_publish(Arc::new(move |topic, payload| {
                let mut got = sink.lock().unwrap();
                let msgs = got.entry(topic.to_string()).or_default();
                if msgs.len() < N {
                    msgs.push(payload.to_vec());
                }
            }))
            .spawn(&session)
            .unwrap();
        let full = || {
            let got = got.lock().unwrap();
            got.len() == rig.topics().len() && got.values().all(|m| m.len() == N)
        };
        let deadline = Instant::now() + Duration::from_secs(60);
        while !full() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(10));
        }
        sim.stop();
        session.close().wait().unwrap();
        assert!(
            full(),
            "the streams did not publish {N} messages each within 60 s"
        );
        let out = std::mem::take(&mut *got.lock().unwrap());
        out
    }

    #[test]
    fn a_seed_fixes_the_live_streams_and_another_seed_changes_them() {
        let rig = small_rig();
        let a = first_messages(&rig, 3);
        assert_eq!(a, first_messages(&rig, 3), "same seed, same messages");
        let other = first_messages(&rig, 4);
        for t in rig.topics() {
            let (mine, theirs) = (&a[&t.topic], &other[&t.topic]);
            // Stamps on the rate's grid but for the seeded jitter (±0.5 ms for cameras and the
            // gripper, ±20 µs for the arm), which is not zero.
            let half_width = if t.topic == "/franka/joint_states" {
                0.02e6
            } else {
                0.5e6
            };
            let period = 1e9 / t.rate_hz;
            let stamps: Vec<u64> = mine
                .iter()
                .map(|m| header_stamp(m).unwrap().as_ns())
                .collect();
            for (k, s) in stamps.iter().enumerate() {
                let jitter = (s - T0) as f64 - k as f64 * period;
                assert!(jitter.abs() <= half_width + 1.0, "{}: {jitter} ns", t.topic);
            }
            let off_grid = stamps
                .iter()
                .enumerate()
                .filter(|(k, s)| ((**s - T0) as f64 - *k as f64 * period).abs() > 1.0)
                .count();
            assert!(off_grid > N / 2, "{}: no jitter", t.topic);
            let their_stamps: Vec<u64> = theirs
                .iter()
                .map(|m| header_stamp(m).unwrap().as_ns())
                .collect();
            assert_ne!(stamps, their_stamps, "{}: same jitter", t.topic);
            if t.is_image {
                let pixels = |m: &[Vec<u8>]| -> Vec<Vec<u8>> {
                    m.iter().map(|x| Image::from_cdr(x).unwrap().data).collect()
                };
                assert!(
                    pixels(mine)
                        .iter()
                        .zip(&pixels(theirs))
                        .all(|(x, y)| x != y),
                    "{}: same pictures under another seed",
                    t.topic
                );
            }
        }
    }
}
