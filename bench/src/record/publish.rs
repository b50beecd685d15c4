//! The load's publisher: one thread per camera (colour, its `camera_info`, depth, its
//! `camera_info`, each frame, as the camera drivers publish them), one per arm, one for `/tf`,
//! each on its own schedule, on zenoh-bridge-ros2dds keys with blocking congestion control (as
//! the simulator publishes). Images are built once, three different frames per stream, and sent
//! without copying: a fresh CDR prefix holding the stamp, then the shared pixels. A gate opens
//! and closes the load around each episode; a thread that falls more than a period behind
//! skips the ticks it missed and counts them, so what was offered and what was sent are both
//! known.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering::SeqCst};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::{anyhow, ensure, Context, Result};
use scaledp_recorder::keys::bridge_key;
use scaledp_schema::msg::{
    CameraInfo, Header, Image, JointState, Quaternion, TfMessage, Time, Transform,
    TransformStamped, Vector3,
};
use scaledp_schema::RosMessage;
use zenoh::bytes::ZBytes;
use zenoh::pubsub::Publisher;
use zenoh::qos::CongestionControl;
use zenoh::Wait;

use super::load::{joint_names, Camera, Load, FPS, JOINT_HZ, TF_HZ};

/// Different frames per image stream.
const VARIANTS: usize = 3;
/// A thread late by less than this sends the ticks it missed at once; later, it skips them.
/// (Less than a camera period: a camera late by a frame drops it.)
const CATCH_UP: Duration = Duration::from_millis(20);

/// Per topic: messages sent and ticks missed (the thread was over a period late).
#[derive(Debug, Default)]
pub struct Count {
    /// Messages put.
    pub sent: AtomicU64,
    /// Payload bytes put.
    pub bytes: AtomicU64,
    /// Ticks skipped.
    pub missed: AtomicU64,
}

/// What the threads share.
struct Shared {
    open: AtomicBool,
    stop: AtomicBool,
    /// Threads between deciding to publish a tick and having published it.
    busy: AtomicUsize,
    counts: Vec<Count>,
}

/// The running publisher.
pub struct LoadPublisher {
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
    topics: Vec<String>,
}

/// A message stream's bytes: the CDR prefix up to the pixels (the stamp at bytes 4..12) and the
/// pixels of each variant.
struct Frames {
    prefix: Vec<u8>,
    pixels: Vec<ZBytes>,
}

fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

fn header(stamp_ns: u64, frame: &str) -> Header {
    Header {
        stamp: Time::from_ns(stamp_ns),
        frame_id: frame.into(),
    }
}

/// A xorshift stream for pixel noise.
fn noise(seed: u64) -> impl FnMut() -> u64 {
    let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    }
}

/// Pixels of variant `v` of a camera's colour or depth: a gradient with per-pixel noise (LZ4
/// gains little on it, as on a camera's frames), depth with holes (NaN, 0) every 31st pixel.
fn pixels(c: &Camera, depth: bool, v: usize) -> Vec<u8> {
    let (w, h) = (c.size.0 as usize, c.size.1 as usize);
    let mut rng = noise((v as u64 + 1) * if depth { 7919 } else { 104_729 });
    let bpp = if depth { c.depth_bpp() } else { c.colour_bpp() } as usize;
    let mut out = Vec::with_capacity(w * h * bpp);
    for y in 0..h {
        for x in 0..w {
            let r = rng();
            let hole = (x + y + v) % 31 == 0;
            match (depth, c.depth_encoding, bpp) {
                (true, "32FC1", _) => {
                    let m = 0.5 + 2.5 * (x + y) as f32 / (w + h) as f32 + (r % 1000) as f32 * 1e-5;
                    out.extend(if hole { f32::NAN } else { m }.to_le_bytes());
                }
                (true, _, _) => {
                    let mm = 500 + (2500 * (x + y) / (w + h)) as u16 + (r % 8) as u16;
                    out.extend(if hole { 0 } else { mm }.to_le_bytes());
                }
                (false, _, _) => {
                    let base = ((x * 255 / w.max(1)) + v * 40) as u8;
                    for ch in 0..bpp {
                        let px = if ch == 3 {
                            255
                        } else {
                            base.wrapping_add((y * 255 / h.max(1)) as u8 / (ch as u8 + 1))
                                .wrapping_add((r >> (8 * ch)) as u8 & 15)
                        };
                        out.push(px);
                    }
                }
            }
        }
    }
    out
}

impl Frames {
    fn of(c: &Camera, depth: bool) -> Result<Frames> {
        let (w, h) = c.size;
        let bpp = if depth { c.depth_bpp() } else { c.colour_bpp() };
        let frame = format!("{}_optical_frame", c.name);
        let mut prefix = Vec::new();
        let mut out = Vec::new();
        for v in 0..VARIANTS {
            let data = pixels(c, depth, v);
            let len = data.len();
            let image = Image {
                header: header(0, &frame),
                height: h,
                width: w,
                encoding: if depth { c.depth_encoding } else { c.encoding }.into(),
                is_bigendian: 0,
                step: w * bpp,
                data,
            };
            let cdr = image.to_cdr();
            ensure!(
                cdr.len() > len && cdr[cdr.len() - len..] == image.data[..],
                "an Image's CDR does not end with its pixels"
            );
            prefix = cdr[..cdr.len() - len].to_vec();
            out.push(ZBytes::from(image.data));
        }
        Ok(Frames {
            prefix,
            pixels: out,
        })
    }

    /// Frame `k` stamped `stamp_ns`: a fresh prefix and the shared pixels.
    fn payload(&self, k: u64, stamp_ns: u64) -> ZBytes {
        let t = Time::from_ns(stamp_ns);
        let mut p = self.prefix.clone();
        p[4..8].copy_from_slice(&t.sec.to_le_bytes());
        p[8..12].copy_from_slice(&t.nanosec.to_le_bytes());
        let mut w = ZBytes::writer();
        w.append(ZBytes::from(p));
        w.append(self.pixels[k as usize % self.pixels.len()].clone());
        w.finish()
    }
}

/// A periodic schedule that restarts whenever the gate opens.
struct Ticker {
    period: Duration,
    t0: Option<Instant>,
    k: u64,
}

impl Ticker {
    fn new(rate_hz: f64) -> Self {
        Self {
            period: Duration::from_secs_f64(1.0 / rate_hz),
            t0: None,
            k: 0,
        }
    }

    /// Waits for the next tick while the gate is open: Some(ticks missed before it), or None
    /// when the gate is closed (or the publisher stops).
    fn next(&mut self, s: &Shared) -> Option<u64> {
        loop {
            if s.stop.load(SeqCst) {
                return None;
            }
            if !s.open.load(SeqCst) {
                self.t0 = None;
                std::thread::sleep(Duration::from_millis(2));
                return None;
            }
            let t0 = *self.t0.get_or_insert_with(|| {
                self.k = 0;
                Instant::now()
            });
            let due = t0 + self.period.mul_f64(self.k as f64);
            let now = Instant::now();
            if now < due {
                std::thread::sleep((due - now).min(Duration::from_millis(20)));
                continue;
            }
            // Late by less than CATCH_UP: the ticks missed go out back to back (a driver's
            // messages delayed by its host); later than that they are skipped, and counted.
            let late = now - due;
            if late < CATCH_UP {
                self.k += 1;
                return Some(0);
            }
            let behind = (late.as_secs_f64() / self.period.as_secs_f64()) as u64;
            self.k += behind + 1;
            return Some(behind);
        }
    }
}

/// Publishes one tick through `f` unless the gate closed meanwhile (see [`LoadPublisher::close`]).
fn tick(s: &Shared, f: impl FnOnce()) {
    s.busy.fetch_add(1, SeqCst);
    if s.open.load(SeqCst) {
        f();
    }
    s.busy.fetch_sub(1, SeqCst);
}

/// Puts `payload` on `p`, counting it under topic `i`.
fn put(s: &Shared, i: usize, p: &Publisher<'_>, payload: ZBytes) {
    let len = payload.len() as u64;
    if p.put(payload).wait().is_ok() {
        s.counts[i].sent.fetch_add(1, SeqCst);
        s.counts[i].bytes.fetch_add(len, SeqCst);
    }
}

fn camera_info(c: &Camera, stamp_ns: u64) -> Vec<u8> {
    let (w, h) = c.size;
    let f = f64::from(w) * 0.95;
    let mut info = CameraInfo::pinhole(
        header(stamp_ns, &format!("{}_optical_frame", c.name)),
        w,
        h,
        f,
        f64::from(w) / 2.0,
        f64::from(h) / 2.0,
    );
    info.d = vec![0.1, -0.2, 0.001, 0.001, 0.05];
    info.to_cdr()
}

impl LoadPublisher {
    /// Declares the publishers of `load` on `session` and starts their threads, the gate closed.
    pub fn start(session: &zenoh::Session, load: &Load) -> Result<Self> {
        let offered = load.offered();
        let topics: Vec<String> = offered.iter().map(|o| o.topic.clone()).collect();
        let shared = Arc::new(Shared {
            open: AtomicBool::new(false),
            stop: AtomicBool::new(false),
            busy: AtomicUsize::new(0),
            counts: topics.iter().map(|_| Count::default()).collect(),
        });
        let index = |t: &str| topics.iter().position(|x| x == t).unwrap_or(0);
        let declare = |t: &str| -> Result<Publisher<'static>> {
            session
                .declare_publisher(bridge_key("", t))
                .congestion_control(CongestionControl::Block)
                .wait()
                .map_err(|e| anyhow!("declaring a publisher on {t}: {e}"))
        };
        let mut threads = Vec::new();
        for c in &load.cameras {
            let colour = (index(&c.topic), declare(&c.topic)?, Frames::of(c, false)?);
            let depth = (
                index(&c.depth_topic),
                declare(&c.depth_topic)?,
                Frames::of(c, true)?,
            );
            let infos = match &c.info_topics {
                Some((ci, di)) => Some(((index(ci), declare(ci)?), (index(di), declare(di)?))),
                None => None,
            };
            let mut all = vec![colour.0, depth.0];
            if let Some(((ci, _), (di, _))) = &infos {
                all.extend([*ci, *di]);
            }
            let (s, c) = (shared.clone(), c.clone());
            threads.push(spawn(&c.name.clone(), move || {
                let mut ticker = Ticker::new(FPS);
                let mut k = 0u64;
                while !s.stop.load(SeqCst) {
                    let Some(missed) = ticker.next(&s) else {
                        continue;
                    };
                    for i in &all {
                        s.counts[*i].missed.fetch_add(missed, SeqCst);
                    }
                    k += missed + 1;
                    tick(&s, || {
                        let stamp = now_ns();
                        put(&s, colour.0, &colour.1, colour.2.payload(k, stamp));
                        if let Some(((i, p), _)) = &infos {
                            put(&s, *i, p, camera_info(&c, stamp).into());
                        }
                        put(&s, depth.0, &depth.1, depth.2.payload(k, stamp));
                        if let Some((_, (i, p))) = &infos {
                            put(&s, *i, p, camera_info(&c, stamp).into());
                        }
                    });
                }
            })?);
        }
        for (arm, topic) in &load.arms {
            let (i, p) = (index(topic), declare(topic)?);
            let (s, names) = (shared.clone(), joint_names(arm));
            threads.push(spawn(arm, move || {
                let mut ticker = Ticker::new(JOINT_HZ);
                let mut k = 0u64;
                while !s.stop.load(SeqCst) {
                    let Some(missed) = ticker.next(&s) else {
                        continue;
                    };
                    s.counts[i].missed.fetch_add(missed, SeqCst);
                    k += missed + 1;
                    tick(&s, || {
                        let t = k as f64 / JOINT_HZ;
                        let q: Vec<f64> = (0..names.len())
                            .map(|j| 0.3 * (t + j as f64).sin())
                            .collect();
                        let js = JointState {
                            header: header(now_ns(), ""),
                            name: names.clone(),
                            velocity: q.iter().map(|v| v * 0.1).collect(),
                            effort: q.iter().map(|v| v * 2.0).collect(),
                            position: q,
                        };
                        put(&s, i, &p, js.to_cdr().into());
                    });
                }
            })?);
        }
        let (i, p) = (index("/tf"), declare("/tf")?);
        let s = shared.clone();
        let links: Vec<(String, String)> = load
            .arms
            .iter()
            .flat_map(|(arm, _)| {
                (0..=6).map(move |l| {
                    let parent = if l == 0 {
                        "world".to_string()
                    } else {
                        format!("{arm}_link{}", l - 1)
                    };
                    (parent, format!("{arm}_link{l}"))
                })
            })
            .collect();
        threads.push(spawn("tf", move || {
            let mut ticker = Ticker::new(TF_HZ);
            while !s.stop.load(SeqCst) {
                let Some(missed) = ticker.next(&s) else {
                    continue;
                };
                s.counts[i].missed.fetch_add(missed, SeqCst);
                tick(&s, || {
                    let stamp = now_ns();
                    let transforms = links
                        .iter()
                        .map(|(parent, child)| TransformStamped {
                            header: header(stamp, parent),
                            child_frame_id: child.clone(),
                            transform: Transform {
                                translation: Vector3 {
                                    x: 0.0,
                                    y: 0.0,
                                    z: 0.1,
                                },
                                rotation: Quaternion {
                                    x: 0.0,
                                    y: 0.0,
                                    z: 0.0,
                                    w: 1.0,
                                },
                            },
                        })
                        .collect();
                    put(&s, i, &p, TfMessage { transforms }.to_cdr().into());
                });
            }
        })?);
        Ok(Self {
            shared,
            threads,
            topics,
        })
    }

    /// The topics, in the order of [`Self::counts`].
    pub fn topics(&self) -> &[String] {
        &self.topics
    }

    /// Per topic: (sent, bytes, missed) so far.
    pub fn counts(&self) -> Vec<(u64, u64, u64)> {
        self.shared
            .counts
            .iter()
            .map(|c| {
                (
                    c.sent.load(SeqCst),
                    c.bytes.load(SeqCst),
                    c.missed.load(SeqCst),
                )
            })
            .collect()
    }

    /// Opens the gate: every thread starts its schedule now.
    pub fn open(&self) {
        self.shared.open.store(true, SeqCst);
    }

    /// Closes the gate and waits (up to `timeout`) until no thread is in the middle of a tick:
    /// after it, the counts are final until the next [`Self::open`].
    pub fn close(&self, timeout: Duration) -> Result<()> {
        self.shared.open.store(false, SeqCst);
        let deadline = Instant::now() + timeout;
        while self.shared.busy.load(SeqCst) > 0 {
            ensure!(
                Instant::now() < deadline,
                "a publisher thread is still putting after {timeout:?}"
            );
            std::thread::sleep(Duration::from_millis(2));
        }
        Ok(())
    }

    /// Stops and joins the threads.
    pub fn stop(self) {
        self.shared.open.store(false, SeqCst);
        self.shared.stop.store(true, SeqCst);
        for t in self.threads {
            let _ = t.join();
        }
    }
}

fn spawn(name: &str, f: impl FnOnce() + Send + 'static) -> Result<JoinHandle<()>> {
    std::thread::Builder::new()
        .name(format!("load:{name}"))
        .spawn(f)
        .with_context(|| format!("starting the publisher thread of {name}"))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn a_frame_is_a_whole_image_with_its_stamp() {
        let load = super::super::load::reference(0.01);
        for c in &load.cameras {
            for depth in [false, true] {
                let f = Frames::of(c, depth).unwrap();
                let stamp = 1_800_000_000_123_456_789;
                let bytes = f.payload(4, stamp).to_bytes().to_vec();
                let img = Image::from_cdr(&bytes).unwrap();
                assert_eq!(img.header.stamp.as_ns(), stamp);
                assert_eq!((img.width, img.height), c.size);
                let bpp = if depth { c.depth_bpp() } else { c.colour_bpp() };
                assert_eq!(img.data.len() as u32, c.size.0 * c.size.1 * bpp);
                assert_eq!(img.step, c.size.0 * bpp);
                // Frame 4 is variant 1, unlike frame 3.
                let other = Image::from_cdr(&f.payload(3, stamp).to_bytes()).unwrap();
                assert_ne!(img.data, other.data);
            }
        }
    }
}
