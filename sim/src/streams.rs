//! The live publishing threads: one per camera, arm and gripper topic, each at the rig's rate.
//!
//! `header.stamp` is the capture time on the rate's grid from the origin plus seeded jitter; the
//! message is built from the world as it is at that instant and leaves a realistic latency
//! later (cameras tens of ms, arms well under one ms), also seeded. A stream whose capture
//! time is already past (an origin in the past) runs flat out.

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use scaledp_recorder::keys::RmwAttachment;
use scaledp_recorder::now_ns;
use scaledp_schema::rig::{Arm, Camera, CameraModel};
use scaledp_schema::RosMessage;
use zenoh::Wait;

use crate::headless::OfflineRun;
use crate::messages;
use crate::render::{self, View};
use crate::runtime::{PublishHook, Shared};
use crate::video::{raw_encoding, video_message, VideoEncoder};

/// What a stream publishes.
// One value per stream thread: the size difference between variants costs nothing.
#[allow(clippy::large_enum_variant)]
pub(crate) enum Kind {
    Camera {
        view: View,
        cam: Camera,
        cache: Vec<Vec<u8>>,
        /// For a camera publishing compressed video.
        encoder: Option<VideoEncoder>,
    },
    Arm {
        index: usize,
        arm: Arm,
    },
    Gripper {
        index: usize,
        arm: Arm,
    },
}

pub(crate) struct Stream {
    pub topic: String,
    pub message_type: &'static str,
    pub rate_hz: f64,
    /// Base latency and the width of its uniform jitter (ms).
    pub latency_ms: (f64, f64),
    /// Half-width of the uniform jitter of capture times (ms).
    pub stamp_jitter_ms: f64,
    pub kind: Kind,
}

pub(crate) struct StreamCtx {
    pub shared: Arc<Shared>,
    pub hook: Option<PublishHook>,
    pub rng: ChaCha8Rng,
    pub t0: u64,
    pub rmw: Option<Vec<u8>>,
    /// Real time: a stream behind by more than a period skips to the current slot (a busy
    /// machine's camera drops frames). Off for an explicit origin: every slot is published.
    pub realtime: bool,
}

/// The rig's streams, cameras first, in `Rig::topics` order (command topics excluded).
pub(crate) fn streams(
    shared: &Shared,
    frame_cache: usize,
    seed: u64,
) -> crate::Result<Vec<Stream>> {
    let scene = shared.scene.clone();
    let rig = &shared.rig;
    let mut out = Vec::new();
    for (i, cam) in rig.cameras.iter().enumerate() {
        let view = View::for_camera(&scene, cam, i);
        // A cache renders the operator's episode at the camera's rate, offline.
        let mut cache = Vec::with_capacity(frame_cache);
        if frame_cache > 0 {
            let mut run = OfflineRun::new(scene.clone(), seed);
            for k in 0..frame_cache {
                run.advance_to((k as f64 * 1e9 / cam.fps) as u64, &mut |_, _| {});
                let mut buf = Vec::new();
                render::render(
                    &scene,
                    &view,
                    &run.world().state(),
                    raw_encoding(cam),
                    &mut buf,
                );
                cache.push(buf);
            }
        }
        let latency_ms = if cam.model == CameraModel::Zed {
            30.0
        } else {
            15.0
        };
        out.push(Stream {
            topic: cam.topic.clone(),
            message_type: cam.message_type(),
            rate_hz: cam.fps,
            latency_ms: (latency_ms, 8.0),
            stamp_jitter_ms: 0.5,
            kind: Kind::Camera {
                view,
                cam: cam.clone(),
                cache,
                encoder: match cam.video_codec() {
                    Some(_) => Some(VideoEncoder::new(cam).map_err(crate::Error::Video)?),
                    None => None,
                },
            },
        });
    }
    for (i, arm) in rig.arms.iter().enumerate() {
        out.push(Stream {
            topic: arm.joint_state_topic.clone(),
            message_type: "sensor_msgs/msg/JointState",
            rate_hz: arm.rate_hz,
            latency_ms: (0.3, 0.4),
            stamp_jitter_ms: 0.02,
            kind: Kind::Arm {
                index: i,
                arm: arm.clone(),
            },
        });
        if let Some(g) = &arm.gripper {
            out.push(Stream {
                topic: g.topic.clone(),
                message_type: "sensor_msgs/msg/JointState",
                rate_hz: g.rate_hz,
                latency_ms: (2.0, 2.0),
                stamp_jitter_ms: 0.5,
                kind: Kind::Gripper {
                    index: i,
                    arm: arm.clone(),
                },
            });
        }
    }
    Ok(out)
}

/// Frames a stream skipped because it fell behind real time, and the warning about it (at most
/// one every five seconds, and only once more than 1 % of the frames went: a 1 kHz joint stream
/// missing a slot now and then is still keeping up).
#[derive(Default)]
struct Lag {
    skipped: u64,
    warned_ns: Option<u64>,
}

impl Lag {
    fn skipped(&mut self, topic: &str, n: u64, published: u64, rate_hz: f64) {
        self.skipped += n;
        let share = published as f64 / (published + self.skipped).max(1) as f64;
        let now = now_ns();
        let due = self
            .warned_ns
            .is_none_or(|t| now.saturating_sub(t) >= 5_000_000_000);
        if due && share < 0.99 {
            self.warned_ns = Some(now);
            tracing::warn!(
                "{topic}: the machine cannot keep up: {} frames skipped so far, publishing at about {:.0} of {rate_hz:.0} Hz",
                self.skipped,
                share * rate_hz
            );
        } else {
            tracing::debug!("{topic}: {n} frames skipped ({} so far)", self.skipped);
        }
    }
}

fn sleep_until(ns: u64) {
    let now = now_ns();
    if ns > now {
        std::thread::sleep(Duration::from_nanos(ns - now));
    }
}

impl Stream {
    /// Publishes until the simulation stops; returns (topic, messages published).
    pub(crate) fn run(
        mut self,
        mut ctx: StreamCtx,
        publisher: zenoh::pubsub::Publisher<'static>,
    ) -> (String, u64) {
        let period_ns = 1e9 / self.rate_hz;
        let mut image_buf = Vec::new();
        // k: the capture slot on the stream's grid; seq: messages published.
        let (mut k, mut seq): (u64, u64) = (0, 0);
        let mut lag = Lag::default();
        while !ctx.shared.stop.load(Ordering::Relaxed) {
            // A sensor that cannot keep up drops frames, as a real camera on a busy machine
            // does: when a slot's instant has passed by more than a period, the next capture
            // is the slot of now, so stamps stay on real time at a lower rate (instead of a
            // backlog whose stamps drift behind every other stream's).
            let now = now_ns();
            let slot_ns = ctx.t0 + (k as f64 * period_ns) as u64;
            if ctx.realtime && now > slot_ns + period_ns as u64 {
                let caught_up = ((now - ctx.t0) as f64 / period_ns).floor() as u64;
                lag.skipped(&self.topic, caught_up - k, seq, self.rate_hz);
                k = caught_up;
            }
            let jitter = ctx.rng.random_range(-1.0..=1.0) * self.stamp_jitter_ms * 1e6;
            let latency =
                (self.latency_ms.0 + ctx.rng.random_range(0.0..=1.0) * self.latency_ms.1) * 1e6;
            let capture_ns = ctx.t0 + (k as f64 * period_ns + jitter).max(0.0) as u64;
            // The world as it is at the capture instant.
            sleep_until(capture_ns);
            if ctx.shared.stop.load(Ordering::Relaxed) {
                break;
            }
            let payload = self.message(&ctx.shared, k, capture_ns, &mut image_buf);
            sleep_until(capture_ns + latency as u64);
            if ctx.shared.stop.load(Ordering::Relaxed) {
                break;
            }
            if let Some(hook) = &ctx.hook {
                hook(&self.topic, &payload);
            }
            let put = publisher.put(payload);
            let put = match &ctx.rmw {
                Some(gid) => put.attachment(
                    RmwAttachment {
                        sequence_number: seq as i64 + 1,
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
            seq += 1;
        }
        (self.topic, seq)
    }

    fn message(
        &mut self,
        shared: &Shared,
        k: u64,
        capture_ns: u64,
        image_buf: &mut Vec<u8>,
    ) -> Vec<u8> {
        match &mut self.kind {
            Kind::Camera {
                view,
                cam,
                cache,
                encoder,
            } => {
                if cache.is_empty() {
                    let state = shared.state();
                    render::render(&shared.scene, view, &state, raw_encoding(cam), image_buf);
                } else {
                    image_buf.clear();
                    image_buf.extend_from_slice(&cache[k as usize % cache.len()]);
                }
                if let Some(enc) = encoder {
                    return video_message(cam, enc, image_buf, capture_ns);
                }
                let image = messages::image(cam, std::mem::take(image_buf), capture_ns);
                let out = image.to_cdr();
                *image_buf = image.data; // reuse the pixel buffer for the next frame
                out
            }
            Kind::Arm { index, arm } => {
                let s = shared.arm_state(*index);
                messages::joint_state(arm, &s, capture_ns).to_cdr()
            }
            Kind::Gripper { index, arm } => {
                let width = shared.arm_state(*index).gripper_width_m;
                match &arm.gripper {
                    Some(g) => messages::gripper_state(g, width, capture_ns).to_cdr(),
                    None => Vec::new(),
                }
            }
        }
    }
}
