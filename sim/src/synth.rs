//! Recordings written straight to disk, faster than real time: the simulated scene rendered at
//! the rig's rates with the same stamps, jitter and latency model as the live simulator, through
//! the recorder's own episode writer. Benchmarks and tests use it for a fixed set of inputs.

use std::path::Path;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scaledp_recorder::EpisodeOptions;
use scaledp_schema::msg::{Header, Image, JointState, Time};
use scaledp_schema::rig::Rig;
use scaledp_schema::{EpisodeMetadata, Label, RosMessage};

use crate::render::{self, View};
use crate::scene::Scene;
use crate::{Error, Result};

/// Changes one message before it is written: (topic, index within the topic, stamp in ns,
/// payload). Tests use it to plant faults.
pub type Mutate<'a> = dyn FnMut(&str, u64, &mut u64, &mut Vec<u8>) + 'a;

/// Writes one episode of `seconds` of `rig` under `seed` to `path` (an `episode_*.mcap` like
/// the recorder's, with `scaledp.episode` metadata naming `task`). Starts at `start_ns`.
pub fn write_episode(
    path: &Path,
    rig: &Rig,
    seed: u64,
    seconds: f64,
    start_ns: u64,
    task: &str,
    mutate: &mut Mutate<'_>,
) -> Result<()> {
    let scene = Scene::new(rig, seed);
    let table_z = render::table_height(&scene);
    let topics = rig.topics();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Plan (log time, topic, k, capture stamp) for every message, then render in log order so
    // only one frame is in memory at a time.
    let mut plan: Vec<(u64, usize, u64, u64)> = Vec::new();
    for (ti, t) in topics.iter().enumerate() {
        let period = 1e9 / t.rate_hz;
        for k in 0..(seconds * t.rate_hz) as u64 {
            let jitter = rng.random_range(-0.5e6..0.5e6) * if t.is_image { 1.0 } else { 0.04 };
            let stamp = start_ns + (k as f64 * period + jitter).max(0.0) as u64;
            let latency = if t.is_image {
                rng.random_range(25e6..35e6)
            } else {
                rng.random_range(3e5..7e5)
            } as u64;
            plan.push((stamp + latency, ti, k, stamp));
        }
    }
    plan.sort_unstable();
    let views: Vec<Option<View>> = topics
        .iter()
        .map(|t| {
            rig.cameras
                .iter()
                .position(|c| c.topic == t.topic)
                .map(|ci| View::for_camera(&scene, &rig.cameras[ci], ci))
        })
        .collect();
    let mut buf = Vec::new();
    let mut message = |ti: usize, stamp: u64| -> Result<Vec<u8>> {
        let t = &topics[ti];
        let t_s = (stamp - start_ns) as f64 * 1e-9;
        let state = scene.state_at(t_s);
        let header = Header {
            stamp: Time::from_ns(stamp),
            frame_id: String::new(),
        };
        if let Some(view) = &views[ti] {
            let cam = rig
                .cameras
                .iter()
                .find(|c| c.topic == t.topic)
                .ok_or_else(|| Error::UnknownTopic {
                    rig: rig.name.clone(),
                    topic: t.topic.clone(),
                })?;
            render::render(&scene, view, &state, cam.encoding(), table_z, &mut buf);
            let channels = render::layout(cam.encoding()).map_or(3, |l| l.0) as u32;
            let img = Image {
                header,
                height: cam.height,
                width: cam.width,
                encoding: cam.encoding().into(),
                is_bigendian: 0,
                step: cam.width * channels,
                data: std::mem::take(&mut buf),
            };
            let out = img.to_cdr();
            buf = img.data;
            return Ok(out);
        }
        let (arm_i, arm) = rig
            .arms
            .iter()
            .enumerate()
            .find(|(_, a)| {
                a.joint_state_topic == t.topic
                    || a.gripper.as_ref().is_some_and(|g| g.topic == t.topic)
            })
            .ok_or_else(|| Error::UnknownTopic {
                rig: rig.name.clone(),
                topic: t.topic.clone(),
            })?;
        let (name, position) = match &arm.gripper {
            Some(g) if g.topic == t.topic => (
                g.joint_names.clone(),
                g.model
                    .positions_for_width(state.arms[arm_i].gripper_width_m, g.joint_names.len()),
            ),
            _ => (arm.joint_names.clone(), state.arms[arm_i].q.clone()),
        };
        let n = name.len();
        Ok(JointState {
            header,
            name,
            position,
            velocity: vec![0.0; n],
            effort: vec![],
        }
        .to_cdr())
    };
    let meta = EpisodeMetadata {
        task: task.to_string(),
        rig_name: rig.name.clone(),
        rig_toml: Some(toml::to_string(rig).map_err(|source| Error::Rig {
            rig: rig.name.clone(),
            source,
        })?),
        start_time_ns: Some(start_ns),
        synthetic: Some(format!("seed {seed}")),
        label: Some(Label::Success),
        ..EpisodeMetadata::default()
    };
    let mut w = EpisodeOptions::new().create(path, &topics, meta.start_record())?;
    for (log_time, ti, k, stamp) in plan {
        let mut payload = message(ti, stamp)?;
        let mut stamp = stamp;
        mutate(&topics[ti].topic, k, &mut stamp, &mut payload);
        w.write(ti, log_time, stamp, &payload)?;
    }
    let meta = EpisodeMetadata {
        end_time_ns: Some(start_ns + (seconds * 1e9) as u64),
        duration_s: Some(seconds),
        message_counts: topics
            .iter()
            .zip(w.message_counts())
            .map(|(t, n)| (t.topic.clone(), *n))
            .collect(),
        ..meta
    };
    w.finish(meta.end_record(), None)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use scaledp_schema::msg::header_stamp;

    use super::*;

    const T0: u64 = 1_700_000_000_000_000_000;

    /// Per topic: (log time, publish time, payload) in file order.
    type Messages = BTreeMap<String, Vec<(u64, u64, Vec<u8>)>>;

    fn messages(bytes: &[u8]) -> Messages {
        let mut out: Messages = BTreeMap::new();
        for m in mcap::MessageStream::new(bytes).unwrap() {
            let m = m.unwrap();
            out.entry(m.channel.topic.clone()).or_default().push((
                m.log_time,
                m.publish_time,
                m.data.to_vec(),
            ));
        }
        out
    }

    #[test]
    fn a_seed_fixes_every_byte_and_another_seed_moves_images_and_stamps() {
        let mut rig = Rig::builtin("franka_2zed").unwrap();
        for c in &mut rig.cameras {
            c.width = 48;
            c.height = 32;
        }
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, seed: u64| {
            let path = dir.path().join(name);
            write_episode(&path, &rig, seed, 1.0, T0, "t", &mut |_, _, _, _| {}).unwrap();
            std::fs::read(path).unwrap()
        };
        let (a, again, other) = (write("a.mcap", 5), write("b.mcap", 5), write("c.mcap", 6));
        assert_eq!(a, again, "same seed, same bytes");
        let (a, other) = (messages(&a), messages(&other));
        assert_eq!(a.len(), rig.topics().len());
        for t in rig.topics() {
            let (mine, theirs) = (&a[&t.topic], &other[&t.topic]);
            assert_eq!(mine.len() as f64, t.rate_hz, "{}: one second", t.topic);
            assert_eq!(mine.len(), theirs.len());
            // Capture stamps: on the rate's grid give or take the jitter (±0.5 ms for cameras,
            // ±20 µs for joints), and the jitter is not zero; the header carries the same stamp.
            let half_width = if t.is_image { 0.5e6 } else { 0.02e6 };
            let period = 1e9 / t.rate_hz;
            let mut off_grid = 0;
            for (k, (log, publish, data)) in mine.iter().enumerate() {
                assert_eq!(header_stamp(data).unwrap().as_ns(), *publish);
                let jitter = (publish - T0) as f64 - k as f64 * period;
                assert!(jitter.abs() <= half_width + 1.0, "{}: {jitter} ns", t.topic);
                off_grid += usize::from(jitter.abs() > 1.0);
                let latency = (log - publish) as f64;
                let (lo, hi) = if t.is_image { (25e6, 35e6) } else { (3e5, 7e5) };
                assert!((lo..=hi).contains(&latency), "{}: {latency} ns", t.topic);
            }
            assert!(off_grid > mine.len() / 2, "{}: no jitter", t.topic);
            // Another seed: other jitter on every topic, other pictures on every camera.
            let stamps = |m: &[(u64, u64, Vec<u8>)]| m.iter().map(|x| x.1).collect::<Vec<_>>();
            assert_ne!(stamps(mine), stamps(theirs), "{}", t.topic);
            if t.is_image {
                let pixels = |m: &[(u64, u64, Vec<u8>)]| -> Vec<Vec<u8>> {
                    m.iter()
                        .map(|x| Image::from_cdr(&x.2).unwrap().data)
                        .collect()
                };
                let (p, q) = (pixels(mine), pixels(theirs));
                assert!(p.iter().zip(&q).all(|(x, y)| x != y), "{}", t.topic);
                // The scene moves: the frames of one seed are not all alike.
                assert_ne!(p[0], p[p.len() - 1], "{}: a still picture", t.topic);
            }
        }
    }
}
