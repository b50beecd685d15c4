//! Foreign bags, bad inputs, live views.

use super::*;

#[test]
fn foreign_bags_show_their_cameras_and_joints() {
    let dir = tempfile::tempdir().unwrap();
    // rosbag2 (mcap storage) of a bimanual UR5 rig with JPEG and PNG CompressedImage cameras,
    // no rig stored: detected as the converter does.
    let expected = run_python("make_foreign_bags.py", &[dir.path()]);
    let bag = dir.path().join("ur_compressed");
    let rrd = dir.path().join("ur.rrd");
    let summary = save(&[&bag], ViewOptions::new(), &rrd);
    assert!(
        summary.shown[0].frames > 0,
        "{:?}",
        summary.shown[0].warnings
    );
    let r = &read(&rrd)[0];
    for (topic, cam) in expected["cameras"].as_object().unwrap() {
        let mut stamps: Vec<i64> = cam["stamps_ns"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_i64().unwrap())
            .collect();
        stamps.sort_unstable();
        let name = topic.trim_start_matches('/').split('/').next().unwrap();
        let path = format!("/cameras/{name}");
        assert_eq!(image_times(r, &path, "capture_time"), stamps, "{path}");
        let media = if cam["format"].as_str().unwrap().contains("png") {
            "image/png"
        } else {
            "image/jpeg"
        };
        assert_eq!(rows(r, &path)[0]["EncodedImage:media_type"], media);
    }
    for arm in ["left", "right"] {
        assert!(!rows(r, &format!("/joints/{arm}")).is_empty());
        assert_eq!(
            scalars(r, &format!("/pose/{arm}/x"), "tick").len(),
            summary.shown[0].frames
        );
        assert!(!rows(r, &format!("/world/{arm}/chain")).is_empty());
    }

    // A ROS 1 bag (lz4 chunks) of the Franka rig: counts and the first joint state.
    let bags = make_bags(dir.path());
    let ros1 = dir.path().join("franka_ros1_lz4.bag");
    let rrd = dir.path().join("ros1.rrd");
    save(&[&ros1], ViewOptions::new(), &rrd);
    let r = &read(&rrd)[0];
    let topics = &bags["files"]["franka_ros1_lz4.bag"]["topics"];
    let count = |t: &str| {
        topics[t]["count"]
            .as_i64()
            .or_else(|| topics[t].as_i64())
            .unwrap_or_else(|| panic!("{t}: {topics}"))
    };
    assert_eq!(
        image_times(r, "/cameras/zed_front", "capture_time").len() as i64,
        count("/zed_front/zed_node/rgb/color/rect/image")
    );
    let joints = scalars(r, "/joints/arm", "capture_time");
    assert_eq!(joints.len() as i64, count("/franka/joint_states"));
    let first = &bags["first"]["/franka/joint_states"];
    assert_eq!(joints[0].0, first["stamp_ns"].as_i64().unwrap());
    let q: Vec<f64> = first["position"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(joints[0].1, q);
}

#[test]
fn bad_inputs_fail_clearly_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bad.rrd");
    let target = Target::Save(out.clone());
    // A path that is no input.
    let notes = dir.path().join("notes.txt");
    std::fs::write(&notes, "not a recording").unwrap();
    let e = view(&[notes.display().to_string()], ViewOptions::new(), &target).unwrap_err();
    assert!(matches!(e, Error::UnknownInput { .. }), "{e}");
    assert!(e.to_string().contains("notes.txt: not an MCAP file"), "{e}");
    no_leftovers(&out);
    // An episode the dataset does not have (checked before anything is written).
    let rig = small_franka();
    let mcap = dir.path().join("episode_000000.mcap");
    synth(&mcap, &rig, 0, 1.0);
    let ds = dir.path().join("ds");
    convert_dataset(std::slice::from_ref(&mcap), &ds);
    let e = view(
        &[ds.display().to_string()],
        ViewOptions::new().episodes(vec![7]),
        &target,
    )
    .unwrap_err();
    assert!(matches!(e, Error::NoSuchEpisode { episode: 7, .. }), "{e}");
    assert!(
        e.to_string().ends_with("no episode 7 (episodes 0..=0)"),
        "{e}"
    );
    no_leftovers(&out);
    // A valid input after a bad one: nothing half-written either.
    let e = view(
        &[mcap.display().to_string(), notes.display().to_string()],
        ViewOptions::new(),
        &target,
    )
    .unwrap_err();
    assert!(matches!(e, Error::UnknownInput { .. }), "{e}");
    no_leftovers(&out);
    // A viewer that cannot be reached.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let url = format!("rerun+http://127.0.0.1:{port}/proxy");
    let e = view(
        &[mcap.display().to_string()],
        ViewOptions::new(),
        &Target::Connect(url.clone()),
    )
    .unwrap_err();
    assert!(matches!(e, Error::Unreachable { .. }), "{e}");
    assert!(
        e.to_string()
            .starts_with(&format!("cannot reach a rerun viewer at {url}")),
        "{e}"
    );
    // A truncated recording shows what it holds and says where it stopped.
    let bytes = std::fs::read(&mcap).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let s = save(&[&cut], ViewOptions::new(), &dir.path().join("cut.rrd"));
    assert!(
        s.shown[0].warnings.iter().any(|w| w.contains("incomplete")),
        "{:?}",
        s.shown[0].warnings
    );
    assert!(s.shown[0].images.values().sum::<u64>() > 0);
}

#[test]
fn live_views_write_what_they_are_given() {
    use scaledp_viewer::{LiveOptions, RecordView, RolloutView, TopicFigures, TrainingView};
    let dir = tempfile::tempdir().unwrap();
    // Training curves on the step timeline.
    let out = dir.path().join("train.rrd");
    let train = TrainingView::start(&Target::Save(out.clone()), "unit").unwrap();
    for step in 0..10u64 {
        train.log_step(step, 1.0 / (step + 1) as f64, 1e-4).unwrap();
    }
    train.log_validation(9, "action_mse", 0.25).unwrap();
    assert_eq!(train.finish().unwrap().as_deref(), Some(out.as_path()));
    let r = &read(&out)[0];
    let loss = scalars(r, "/train/loss", "step");
    assert_eq!(loss.len(), 10);
    assert_eq!(loss[3], (3, vec![0.25]));
    assert_eq!(scalars(r, "/val/action_mse", "step"), vec![(9, vec![0.25])]);

    // A rollout: an image, state and action, a predicted chunk.
    let rig = small_franka();
    let out = dir.path().join("rollout.rrd");
    let roll = RolloutView::start(
        &Target::Save(out.clone()),
        "eval 0",
        &rig,
        scaledp_schema::ActionSpace::Tcp,
    )
    .unwrap();
    roll.set_time(0, 0.0);
    roll.log_image("front", &[128u8; 8 * 6 * 3], 8, 6).unwrap();
    let state: Vec<f32> = (0..7).map(|i| i as f32 * 0.1).collect();
    let action: Vec<f32> = (0..7).map(|i| i as f32 * 0.2).collect();
    let q = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
    roll.log_step(&state, &action, Some(&q)).unwrap();
    roll.log_chunk(&[0.1; 7 * 16], 7).unwrap();
    roll.finish().unwrap();
    let r = &read(&out)[0];
    assert_eq!(image_times(r, "/cameras/front", "step"), vec![0]);
    assert_eq!(
        scalars(r, "/pose/arm/y", "step"),
        vec![(0, vec![f64::from(0.1f32), f64::from(0.2f32)])]
    );
    assert_eq!(rows(r, "/world/arm/chain").len(), 1);
    assert_eq!(
        rows(r, "/world/arm/predicted_chunk")[0]["LineStrips3D:strips"],
        serde_json::json!([16])
    );

    // The live recorder view, fed as the Zenoh tap feeds it: one frame and one joint state per
    // topic pass the rate limit, the figures become rates.
    let out = dir.path().join("live.rrd");
    let live = RecordView::start(&Target::Save(out.clone()), &rig, LiveOptions::default()).unwrap();
    let mcap = dir.path().join("episode_000000.mcap");
    synth(&mcap, &rig, 0, 0.5);
    let src = scaledp_converter::read_input(&mcap).unwrap();
    // The synthetic episode holds the training streams only: the rig's depth, camera_info and
    // /tf topics have no message in it and stay unfed.
    let mut fed = Vec::new();
    for (i, t) in live.topics().to_vec().iter().enumerate() {
        let Some(m) = src.messages.iter().find(|m| m.topic == t.topic) else {
            continue;
        };
        live.message(i, &m.data);
        live.message(i, &m.data); // within the rate limit: skipped
        fed.push(t.topic.clone());
    }
    assert!(
        fed.iter().any(|t| t == "/franka/joint_states") && fed.len() >= 4,
        "{fed:?}"
    );
    let figures = |n: u64| {
        live.topics()
            .iter()
            .map(|t| TopicFigures {
                topic: t.topic.clone(),
                received: n,
                bytes: n * 1000,
                dropped: 0,
                upstream_gaps: 0,
            })
            .collect::<Vec<_>>()
    };
    live.status(figures(0), 0);
    std::thread::sleep(std::time::Duration::from_millis(100));
    live.status(figures(10), 1 << 20);
    live.event("episode 0 started");
    live.finish().unwrap();
    let r = &read(&out)[0];
    assert_eq!(image_times(r, "/cameras/front", "receive_time").len(), 1);
    assert_eq!(rows(r, "/joints/arm").len(), 1);
    assert_eq!(rows(r, "/gripper/arm").len(), 1);
    let rate = scalars(r, "/recorder/rate_hz/franka/joint_states", "receive_time");
    assert_eq!(rate.len(), 1);
    assert!(rate[0].1[0] > 10.0, "{rate:?}");
    assert!(rows(r, "/log")
        .iter()
        .any(|row| row["TextLog:text"] == "episode 0 started"));
}
