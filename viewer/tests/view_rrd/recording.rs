//! A recording: every camera frame and joint state, and the episode as converted.

use super::*;

#[test]
fn a_recording_shows_every_frame_every_joint_state_and_the_converted_episode() {
    let dir = tempfile::tempdir().unwrap();
    let rig = small_franka();
    let mcap = dir.path().join("episode_000000.mcap");
    synth(&mcap, &rig, 0, 2.0);
    let out = dir.path().join("rec.rrd");
    let summary = save(&[&mcap], ViewOptions::new(), &out);
    assert_eq!(summary.saved.as_deref(), Some(out.as_path()));
    assert_eq!(summary.shown.len(), 1);
    let recs = read(&out);
    assert_eq!(recs.len(), 1);
    let r = &recs[0];
    assert_eq!(r["application_id"], "scaledp");
    assert_eq!(r["name"], "episode_000000.mcap");

    // The source, read by the converter's reader.
    let src = scaledp_converter::read_input(&mcap).unwrap();
    for cam in &rig.cameras {
        let mut stamps: Vec<i64> = src
            .messages
            .iter()
            .filter(|m| m.topic == cam.topic)
            .map(|m| scaledp_schema::msg::header_stamp(&m.data).unwrap().as_ns() as i64)
            .collect();
        stamps.sort_unstable();
        assert!(stamps.len() >= 55, "{} frames", stamps.len());
        let path = format!("/cameras/{}", cam.name);
        assert_eq!(
            image_times(r, &path, "capture_time"),
            stamps,
            "{path}: every frame once"
        );
        let first = &rows(r, &path)[0];
        assert_eq!(first["Image:format"][0], 64);
        assert_eq!(
            first["Image:buffer"]["bytes"],
            64 * 48 * 4,
            "bgra8 as stored"
        );
        assert_eq!(
            summary.shown[0].images[&format!("cameras/{}", cam.name)],
            stamps.len() as u64
        );
    }
    // Joint positions: every message, in the rig's joint order, values as sent.
    let arm = &rig.arms[0];
    let mut want: Vec<(i64, Vec<f64>)> = src
        .messages
        .iter()
        .filter(|m| m.topic == arm.joint_state_topic)
        .map(|m| {
            let js = JointState::from_cdr(&m.data).unwrap();
            let q = arm
                .joint_names
                .iter()
                .map(|n| js.position[js.name.iter().position(|x| x == n).unwrap()])
                .collect();
            (js.header.stamp.as_ns() as i64, q)
        })
        .collect();
    want.sort_by_key(|a| a.0);
    assert_eq!(want.len(), 2000);
    assert_eq!(scalars(r, "/joints/arm", "capture_time"), want);
    assert_eq!(
        entity(r, "/joints/arm")["static"]["SeriesLines:names"],
        serde_json::json!(arm.joint_names)
    );
    let widths = scalars(r, "/gripper/arm", "capture_time");
    assert_eq!(widths.len(), 100);
    assert!(widths
        .iter()
        .all(|(_, w)| w.len() == 1 && (0.0..=0.08).contains(&w[0])));

    // State and action per tick: what the converter computes for this recording.
    let opts = ConvertOptions::default().size(64, 48).depth(false);
    let ep = convert(&mcap, &src, &InMemory(&src), &opts).unwrap();
    assert_eq!(summary.shown[0].frames, ep.len());
    for (d, dim) in ["x", "y", "z", "roll", "pitch", "yaw", "gripper"]
        .iter()
        .enumerate()
    {
        let got = scalars(r, &format!("/pose/arm/{dim}"), "tick");
        assert_eq!(got.len(), ep.len(), "{dim}");
        for (t, (tick, v)) in got.iter().enumerate() {
            assert_eq!(*tick, t as i64);
            assert_eq!(
                v,
                &vec![
                    f64::from(ep.state[t * 7 + d]),
                    f64::from(ep.action[t * 7 + d])
                ],
                "{dim} at tick {t}"
            );
        }
        assert_eq!(
            entity(r, &format!("/pose/arm/{dim}"))["static"]["SeriesLines:names"],
            serde_json::json!(["state", "action"])
        );
    }
    // Ticks on the capture timeline, 100 ms apart at 10 Hz.
    let ticks: Vec<i64> = scalars(r, "/pose/arm/x", "capture_time")
        .iter()
        .map(|x| x.0)
        .collect();
    assert!(
        ticks
            .windows(2)
            .all(|w| (w[1] - w[0] - 100_000_000).abs() <= 1),
        "{ticks:?}"
    );
    // 3-D: the chain, link frames, TCP per tick; trajectory static; the chunk ahead.
    assert_eq!(rows(r, "/world/arm/chain").len(), ep.len());
    assert_eq!(rows(r, "/world/arm/links/8").len(), ep.len());
    assert_eq!(rows(r, "/world/arm/tcp").len(), ep.len());
    assert_eq!(rows(r, "/world/arm/action_chunk").len(), ep.len());
    assert_eq!(
        entity(r, "/world/arm/tcp_trajectory")["static"]["LineStrips3D:strips"],
        serde_json::json!([ep.len()])
    );
    // The TCP translation is the state's x, y, z.
    let mut tcp = rows(r, "/world/arm/tcp");
    tcp.sort_by_key(|row| row["tick"].as_i64());
    for (t, row) in tcp.iter().enumerate() {
        let xyz: Vec<f64> = row["Transform3D:translation"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        for k in 0..3 {
            assert!(
                (xyz[k] - f64::from(ep.state[t * 7 + k])).abs() < 1e-5,
                "tick {t}: {xyz:?}"
            );
        }
    }
    // Quality: skew per tick (synchronised cameras), no invalid tick; the metadata as text.
    let skew = scalars(r, "/quality/camera_skew_ms", "tick");
    assert_eq!(skew.len(), ep.len() + 1);
    assert!(skew.iter().all(|(_, s)| s[0] < 2.0), "{skew:?}");
    assert!(entity(r, "/quality/invalid_ticks")["rows"]
        .as_array()
        .unwrap()
        .is_empty());
    let text: Vec<String> = rows(r, "/log")
        .iter()
        .map(|r| r["TextLog:text"].as_str().unwrap().to_string())
        .collect();
    assert!(
        text.contains(&"task: stack the cubes".to_string()),
        "{text:?}"
    );
    assert!(text.iter().any(|t| t.starts_with("outcome: ")), "{text:?}");
}
