//! The live publishing threads: one per camera, arm and gripper, and one for `/tf`, each at the
//! rig's rate. A camera's thread publishes, with the same capture stamp, its colour image and
//! what its driver publishes beside it when the rig lists it: registered depth, the colour
//! image's and the depth image's `camera_info`.
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
use scaledp_schema::rig::{Arm, Camera, CameraModel, CAMERA_INFO, TF_MESSAGE};
use scaledp_schema::RosMessage;
use zenoh::Wait;

use crate::depth::{camera_info, DepthSensor};
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
        /// Registered depth, when the rig lists it (its output follows the colour image's).
        depth: Option<DepthSensor>,
        /// How many `camera_info` outputs follow (the colour image's, then the depth's).
        infos: usize,
    },
    /// `/tf`: every arm's flange in its base.
    Tf,
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
    /// What it publishes, (topic, type) each, in the order [`Stream::message`] makes them.
    pub outputs: Vec<(String, &'static str)>,
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
        let mut outputs = vec![(cam.topic.clone(), cam.message_type())];
        let depth = match &cam.depth {
            Some(d) if d.compressed => {
                tracing::warn!(
                    "{}: the simulator publishes raw depth only; this compressedDepth topic stays silent",
                    d.topic
                );
                None
            }
            Some(d) => {
                outputs.push((d.topic.clone(), d.message_type()));
                Some(DepthSensor::new(d.encoding))
            }
            None => None,
        };
        let infos = [
            cam.camera_info_topic.as_ref(),
            cam.depth
                .as_ref()
                .and_then(|d| d.camera_info_topic.as_ref()),
        ];
        for t in infos.iter().flatten() {
            outputs.push(((*t).clone(), CAMERA_INFO));
        }
        out.push(Stream {
            outputs,
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
                depth,
                infos: infos.iter().flatten().count(),
            },
        });
    }
    for (i, arm) in rig.arms.iter().enumerate() {
        out.push(Stream {
            outputs: vec![(arm.joint_state_topic.clone(), JOINT_STATE)],
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
                outputs: vec![(g.topic.clone(), JOINT_STATE)],
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
    if let Some(tf) = rig.tf.as_ref().filter(|t| t.dynamic) {
        out.push(Stream {
            outputs: vec![(tf.topic.clone(), TF_MESSAGE)],
            rate_hz: tf.rate_hz.unwrap_or(crate::tf::DEFAULT_TF_RATE_HZ),
            latency_ms: (1.0, 1.0),
            stamp_jitter_ms: 0.2,
            kind: Kind::Tf,
        });
    }
    Ok(out)
}

const JOINT_STATE: &str = "sensor_msgs/msg/JointState";

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
    /// Publishes until the simulation stops, output `j` on `publishers[j]`; returns (topic,
    /// messages published) per output.
    pub(crate) fn run(
        mut self,
        mut ctx: StreamCtx,
        publishers: Vec<zenoh::pubsub::Publisher<'static>>,
    ) -> Vec<(String, u64)> {
        let period_ns = 1e9 / self.rate_hz;
        let mut image_buf = Vec::new();
        let topic = self.outputs[0].0.clone();
        // k: the capture slot on the stream's grid; seq: captures published.
        let (mut k, mut seq): (u64, u64) = (0, 0);
        let mut sent = vec![0u64; self.outputs.len()];
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
                lag.skipped(&topic, caught_up - k, seq, self.rate_hz);
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
            let payloads = self.message(&ctx.shared, k, capture_ns, &mut image_buf);
            sleep_until(capture_ns + latency as u64);
            if ctx.shared.stop.load(Ordering::Relaxed) {
                break;
            }
            for (j, ((out_topic, _), payload)) in self.outputs.iter().zip(payloads).enumerate() {
                if let Some(hook) = &ctx.hook {
                    hook(out_topic, &payload);
                }
                let put = publishers[j].put(payload);
                let put = match &ctx.rmw {
                    Some(gid) => {
                        // One gid per publisher: the stream's, its last byte told apart.
                        let mut gid = gid.clone();
                        if let Some(last) = gid.last_mut() {
                            *last ^= j as u8;
                        }
                        put.attachment(
                            RmwAttachment {
                                sequence_number: sent[j] as i64 + 1,
                                source_timestamp_ns: now_ns() as i64,
                                source_gid: gid,
                            }
                            .to_zbytes(),
                        )
                    }
                    None => put,
                };
                if let Err(e) = put.wait() {
                    tracing::warn!("{out_topic}: {e}");
                }
                sent[j] += 1;
            }
            k += 1;
            seq += 1;
        }
        self.outputs
            .iter()
            .map(|(t, _)| t.clone())
            .zip(sent)
            .collect()
    }

    /// The payloads of one capture, one per output.
    fn message(
        &mut self,
        shared: &Shared,
        k: u64,
        capture_ns: u64,
        image_buf: &mut Vec<u8>,
    ) -> Vec<Vec<u8>> {
        match &mut self.kind {
            Kind::Camera {
                view,
                cam,
                cache,
                encoder,
                depth,
                infos,
            } => {
                let state = (cache.is_empty() || depth.is_some()).then(|| shared.state());
                match (&state, cache.is_empty()) {
                    (Some(state), true) => {
                        render::render(&shared.scene, view, state, raw_encoding(cam), image_buf)
                    }
                    _ => {
                        image_buf.clear();
                        image_buf.extend_from_slice(&cache[k as usize % cache.len()]);
                    }
                }
                let color = if let Some(enc) = encoder {
                    video_message(cam, enc, image_buf, capture_ns)
                } else {
                    let image = messages::image(cam, std::mem::take(image_buf), capture_ns);
                    let out = image.to_cdr();
                    *image_buf = image.data; // reuse the pixel buffer for the next frame
                    out
                };
                let mut out = vec![color];
                if let (Some(sensor), Some(state)) = (depth.as_mut(), &state) {
                    out.push(sensor.message(cam, &shared.scene, view, state, capture_ns));
                }
                for _ in 0..*infos {
                    out.push(camera_info(cam, view, capture_ns).to_cdr());
                }
                out
            }
            Kind::Arm { index, arm } => {
                let s = shared.arm_state(*index);
                vec![messages::joint_state(arm, &s, capture_ns).to_cdr()]
            }
            Kind::Gripper { index, arm } => {
                let width = shared.arm_state(*index).gripper_width_m;
                vec![match &arm.gripper {
                    Some(g) => messages::gripper_state(g, width, capture_ns).to_cdr(),
                    None => Vec::new(),
                }]
            }
            Kind::Tf => {
                let state = shared.state();
                vec![crate::tf::tf_dynamic(&shared.scene, &state, capture_ns).to_cdr()]
            }
        }
    }
}
