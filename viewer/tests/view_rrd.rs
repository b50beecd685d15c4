//! `.rrd` files of a recording, a converted dataset and foreign bags, read back with the
//! `rerun-sdk` Python package (`tests/py/read_rrd.py`, pinned in tests/py/requirements.txt):
//! entity paths, every camera frame / dataset frame exactly once, scalars equal to the source.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use scaledp_converter::{convert, ConvertOptions, InMemory};
use scaledp_schema::msg::JointState;
use scaledp_schema::{Rig, RosMessage};
use scaledp_testkit::{make_bags, run_python};
use scaledp_viewer::{view, Error, Prediction, Target, ViewOptions};
use serde_json::Value;

/// Start of the first synthetic episode (ns).
const T0: u64 = 1_700_000_000_000_000_000;

/// The Franka rig with its real topics, encodings and rates, but 64×48 images.
fn small_franka() -> Rig {
    let mut rig = Rig::builtin("franka_2zed").unwrap();
    for c in &mut rig.cameras {
        c.width = 64;
        c.height = 48;
    }
    rig
}

fn synth(path: &Path, rig: &Rig, seed: u64, seconds: f64) {
    scaledp_sim::write_episode(
        path,
        rig,
        seed,
        seconds,
        T0 + seed * 100_000_000_000,
        "stack the cubes",
        &mut |_, _, _, _| {},
    )
    .unwrap();
}

fn save(paths: &[&Path], opts: ViewOptions, out: &Path) -> scaledp_viewer::Summary {
    let paths: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
    view(&paths, opts, &Target::Save(out.into())).unwrap()
}

fn read(rrd: &Path) -> Vec<Value> {
    let v = run_python("read_rrd.py", &[rrd]);
    v["recordings"].as_array().unwrap().clone()
}

fn entity<'a>(rec: &'a Value, path: &str) -> &'a Value {
    rec["entities"].get(path).unwrap_or_else(|| {
        panic!(
            "no entity {path}; have {:?}",
            rec["entities"]
                .as_object()
                .unwrap()
                .keys()
                .collect::<Vec<_>>()
        )
    })
}

fn rows(rec: &Value, path: &str) -> Vec<Value> {
    entity(rec, path)["rows"].as_array().unwrap().clone()
}

/// (timeline value, scalars) of every row of a scalar entity, sorted by the timeline.
fn scalars(rec: &Value, path: &str, timeline: &str) -> Vec<(i64, Vec<f64>)> {
    let mut out: Vec<(i64, Vec<f64>)> = rows(rec, path)
        .iter()
        .map(|r| {
            let t = r[timeline]
                .as_i64()
                .unwrap_or_else(|| panic!("{path}: row without {timeline}: {r}"));
            let v = r["Scalars:scalars"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap_or(f64::NAN))
                .collect();
            (t, v)
        })
        .collect();
    out.sort_by(|a, b| {
        a.0.cmp(&b.0)
            .then(a.1.partial_cmp(&b.1).unwrap_or(std::cmp::Ordering::Equal))
    });
    out
}

/// Sorted values of `timeline` of every row of an image entity.
fn image_times(rec: &Value, path: &str, timeline: &str) -> Vec<i64> {
    let mut t: Vec<i64> = rows(rec, path)
        .iter()
        .filter(|r| r.get("Image:buffer").is_some() || r.get("EncodedImage:blob").is_some())
        .map(|r| r[timeline].as_i64().unwrap())
        .collect();
    t.sort_unstable();
    t
}

fn no_leftovers(out: &Path) {
    let mut partial = out.as_os_str().to_os_string();
    partial.push(".partial");
    assert!(!out.exists(), "{} was written", out.display());
    assert!(!Path::new(&partial).exists(), "a partial file was left");
}

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
    let opts = ConvertOptions::default().size(64, 48);
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

/// Converts `inputs` into a dataset at `out` with the converter library.
fn convert_dataset(inputs: &[PathBuf], out: &Path) {
    let opts = scaledp_converter::JobOptions::default()
        .convert(ConvertOptions::default().size(64, 48))
        .jobs(1);
    let results = scaledp_converter::run(inputs, out, &opts, &|_| {}).unwrap();
    assert!(
        results
            .iter()
            .all(|(_, o)| matches!(o, scaledp_converter::InputResult::Converted(_))),
        "{results:?}"
    );
}

/// Per row of the first data file: (episode, frame, column values) for float list columns and
/// sha256 of image bytes.
fn data_rows(ds: &Path) -> Vec<BTreeMap<String, Value>> {
    use arrow_array::cast::AsArray;
    use arrow_array::Array;
    let file = std::fs::File::open(ds.join("data/chunk-000/file-000.parquet")).unwrap();
    let mut out = Vec::new();
    for batch in parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
        .unwrap()
        .build()
        .unwrap()
    {
        let batch = batch.unwrap();
        for i in 0..batch.num_rows() {
            let mut row = BTreeMap::new();
            for (f, c) in batch.schema().fields().iter().zip(batch.columns()) {
                let v = match c.data_type() {
                    arrow_schema::DataType::Int64 => {
                        Value::from(c.as_primitive::<arrow_array::types::Int64Type>().value(i))
                    }
                    arrow_schema::DataType::FixedSizeList(..) => {
                        let l = c.as_fixed_size_list().value(i);
                        Value::from(
                            l.as_primitive::<arrow_array::types::Float32Type>()
                                .values()
                                .iter()
                                .map(|&x| f64::from(x))
                                .collect::<Vec<_>>(),
                        )
                    }
                    arrow_schema::DataType::Struct(_) => {
                        let b = c
                            .as_struct()
                            .column_by_name("bytes")
                            .unwrap()
                            .as_binary::<i32>()
                            .value(i)
                            .to_vec();
                        Value::from(b.len())
                    }
                    _ => continue,
                };
                row.insert(f.name().clone(), v);
            }
            out.push(row);
        }
    }
    out
}

#[test]
fn a_dataset_shows_every_stored_frame_once_and_its_state_and_action() {
    let dir = tempfile::tempdir().unwrap();
    let rig = small_franka();
    let inputs: Vec<PathBuf> = (0..2)
        .map(|k| {
            let p = dir.path().join(format!("episode_{k:06}.mcap"));
            synth(&p, &rig, k, 2.0);
            p
        })
        .collect();
    let ds = dir.path().join("ds");
    convert_dataset(&inputs, &ds);
    let out = dir.path().join("ds.rrd");
    let summary = save(&[&ds], ViewOptions::new(), &out);
    assert_eq!(summary.shown.len(), 2);
    let recs = read(&out);
    assert_eq!(recs.len(), 2);
    let stored = data_rows(&ds);
    for r in &recs {
        let ep: i64 = r["recording_id"]
            .as_str()
            .unwrap()
            .rsplit('#')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        let mine: Vec<&BTreeMap<String, Value>> = stored
            .iter()
            .filter(|row| row["episode_index"] == ep)
            .collect();
        let n = mine.len() as i64;
        assert!(n > 10);
        for cam in ["front", "wrist"] {
            let path = format!("/cameras/{cam}");
            assert_eq!(
                image_times(r, &path, "frame_index"),
                (0..n).collect::<Vec<_>>(),
                "{path}: every stored frame once"
            );
            let mut by_frame = rows(r, &path);
            by_frame.sort_by_key(|row| row["frame_index"].as_i64());
            for (row, src) in by_frame.iter().zip(&mine) {
                assert_eq!(
                    row["EncodedImage:blob"]["bytes"],
                    src[&format!("observation.images.{cam}")],
                    "JPEG passed through"
                );
                assert_eq!(row["EncodedImage:media_type"], "image/jpeg");
            }
        }
        for (d, dim) in ["x", "y", "z", "roll", "pitch", "yaw", "gripper"]
            .iter()
            .enumerate()
        {
            let got = scalars(r, &format!("/pose/arm/{dim}"), "frame_index");
            assert_eq!(got.len() as i64, n, "{dim}");
            for ((f, v), src) in got.iter().zip(&mine) {
                assert_eq!(*f, src["frame_index"].as_i64().unwrap());
                let s = src["observation.state"][d].as_f64().unwrap();
                let a = src["action"][d].as_f64().unwrap();
                assert_eq!(v, &vec![s, a], "{dim} frame {f}");
            }
        }
        assert_eq!(
            rows(r, "/world/arm/chain").len() as i64,
            n,
            "3-D from observation.joints"
        );
        let text: Vec<String> = rows(r, "/log")
            .iter()
            .map(|r| r["TextLog:text"].as_str().unwrap().to_string())
            .collect();
        assert!(
            text.contains(&"task: stack the cubes".to_string()),
            "{text:?}"
        );
    }
    // One episode, downsampled.
    // One episode, downsampled, with a policy's chunks (4 steps of 7) at every other frame.
    let one = dir.path().join("one.rrd");
    let frames: Vec<i64> = (0..stored.iter().filter(|r| r["episode_index"] == 1).count() as i64)
        .step_by(2)
        .collect();
    let prediction = Prediction {
        frames: frames.clone(),
        values: (0..frames.len() * 4 * 7).map(|i| i as f32 * 1e-3).collect(),
    };
    let s = save(
        &[&ds],
        ViewOptions::new()
            .episodes(vec![1])
            .max_width(Some(32))
            .prediction(1, prediction.clone()),
        &one,
    );
    assert_eq!(s.shown.len(), 1);
    let recs = read(&one);
    assert_eq!(recs.len(), 1);
    assert!(recs[0]["recording_id"].as_str().unwrap().ends_with("#1"));
    let mut predicted = rows(&recs[0], "/world/arm/predicted_chunk");
    predicted.sort_by_key(|row| row["frame_index"].as_i64());
    let at: Vec<i64> = predicted
        .iter()
        .map(|row| row["frame_index"].as_i64().unwrap())
        .collect();
    assert_eq!(
        at, frames,
        "a predicted chunk at each predicted frame, once"
    );
    for row in &predicted {
        assert_eq!(
            row["LineStrips3D:strips"],
            serde_json::json!([4]),
            "C points"
        );
    }
    // Chunks that do not fit the dataset's 7 action dimensions: an error naming the dataset.
    let bad = Prediction {
        frames: vec![0, 1],
        values: vec![0.0; 2 * 4 * 5],
    };
    let err = scaledp_viewer::view(
        &[ds.to_string_lossy().to_string()],
        ViewOptions::new().episodes(vec![1]).prediction(1, bad),
        &Target::Save(dir.path().join("bad.rrd")),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("do not fit 7 action dimensions"), "{err}");
}

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
    for (i, t) in live.topics().to_vec().iter().enumerate() {
        let m = src.messages.iter().find(|m| m.topic == t.topic).unwrap();
        live.message(i, &m.data);
        live.message(i, &m.data); // within the rate limit: skipped
    }
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
