//! The offline writer: a seed fixes every byte; the operator's episode succeeds and its commands
//! are written.

use std::collections::BTreeMap;

use scaledp_schema::msg::{header_stamp, Image, JointState, PoseStamped};

use super::*;

const T0: u64 = 1_700_000_000_000_000_000;

/// Per topic: (log time, publish time, payload) in file order.
type Messages = BTreeMap<String, Vec<(u64, u64, Vec<u8>)>>;

fn messages(bytes: &[u8]) -> Messages {
    let mut out: Messages = BTreeMap::new();
    let mut last_log = 0;
    for m in mcap::MessageStream::new(bytes).unwrap() {
        let m = m.unwrap();
        assert!(m.log_time >= last_log, "written out of receive order");
        last_log = m.log_time;
        out.entry(m.channel.topic.clone()).or_default().push((
            m.log_time,
            m.publish_time,
            m.data.to_vec(),
        ));
    }
    out
}

fn small(name: &str, w: u32, h: u32) -> Rig {
    Rig::builtin(name).unwrap().with_image_size(w, h)
}

#[test]
fn a_seed_fixes_every_byte_and_another_seed_moves_images_and_stamps() {
    let rig = small("franka_2zed", 48, 32);
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, seed: u64| {
        let path = dir.path().join(name);
        write_episode(&path, &rig, seed, 1.0, T0, "t", &mut |_, _, _, _| {}).unwrap();
        std::fs::read(path).unwrap()
    };
    let (a, again, other) = (write("a.mcap", 5), write("b.mcap", 5), write("c.mcap", 6));
    assert_eq!(a, again, "same seed, same bytes");
    let (a, other) = (messages(&a), messages(&other));
    assert_eq!(a.len(), rig.training_topics().len());
    for t in rig.training_topics() {
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

#[test]
fn the_operators_episode_succeeds_is_labelled_and_carries_its_commands() {
    for (name, seed) in [("franka_sim", 11), ("bimanual_ur5_sim", 12)] {
        let rig = small(name, 32, 24);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("episode_000000.mcap");
        let r = write_episode(&path, &rig, seed, 14.0, T0, "t", &mut |_, _, _, _| {}).unwrap();
        assert!(r.operator_done && r.task.success, "{name}: {:?}", r.task);
        let bytes = std::fs::read(&path).unwrap();
        let msgs = messages(&bytes);
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let meta = summary
            .metadata_indexes
            .iter()
            .any(|m| m.name == "scaledp.episode");
        assert!(meta, "{name}: no end record");
        let mut outcome = None;
        for idx in &summary.metadata_indexes {
            let m = mcap::read::metadata(&bytes, idx).unwrap();
            if m.name == "scaledp.episode" {
                outcome = m.metadata.get("outcome").cloned();
            }
        }
        assert_eq!(outcome.as_deref(), Some("success"), "{name}");
        for arm in &rig.arms {
            let poses = &msgs[arm.command_topic.as_ref().unwrap()];
            // 100 Hz leader samples for 14 s.
            assert_eq!(poses.len(), 1400, "{name}");
            let first = PoseStamped::from_cdr(&poses[0].2).unwrap();
            assert_eq!(first.header.stamp.as_ns(), T0);
            let z: Vec<f64> = poses
                .iter()
                .map(|p| PoseStamped::from_cdr(&p.2).unwrap().pose.position.z)
                .collect();
            let (lo, hi) = z
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(*v), b.max(*v)));
            assert!(
                hi - lo > 0.2,
                "{name}: the commanded TCP moved {} m up and down",
                hi - lo
            );
            let g = arm.gripper.as_ref().unwrap();
            let grips = &msgs[g.command_topic.as_ref().unwrap()];
            let widths: Vec<f64> = grips
                .iter()
                .map(|m| {
                    g.model
                        .width_m(&JointState::from_cdr(&m.2).unwrap().position)
                })
                .collect();
            assert!(widths.iter().any(|w| *w < 0.005) && widths.iter().any(|w| *w > 0.079));
        }
    }
}
