//! A recording with registered depth and tf, viewed into an `.rrd` and read back with the
//! `rerun-sdk` Python package (`tests/py/read_rrd.py`): every depth frame a `DepthImage` on
//! `depth/<camera>` with the millimetre meter, every `/tf` transform at its capture time and
//! every `/tf_static` one as static, each on its child frame's entity with its frames named.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use scaledp_schema::msg::{
    Header, Image, Quaternion, TfMessage, Time, Transform, TransformStamped, Vector3,
};
use scaledp_schema::{EpisodeMetadata, Rig, RosMessage};
use scaledp_testkit::run_python;
use scaledp_viewer::{view, Target, ViewOptions};

const T0: u64 = 1_800_000_000_000_000_000;
const RIG: &str = r#"
name = "depth_view"
control_rate_hz = 10.0

[[camera]]
name = "cam"
topic = "/cam/color"
model = "realsense"
width = 8
height = 6
fps = 30.0

[camera.depth]
topic = "/cam/depth"
encoding = "16UC1"
"#;

fn transform(stamp: u64, parent: &str, child: &str, x: f64) -> TransformStamped {
    TransformStamped {
        header: Header {
            stamp: Time::from_ns(stamp),
            frame_id: parent.into(),
        },
        child_frame_id: child.into(),
        transform: Transform {
            translation: Vector3 { x, y: 0.0, z: 0.5 },
            rotation: Quaternion::default(),
        },
    }
}

fn write(path: &Path) {
    let rig = Rig::parse(RIG, Path::new("depth_view.toml")).unwrap();
    let meta = EpisodeMetadata {
        task: "look".into(),
        rig_name: rig.name.clone(),
        rig_toml: Some(RIG.to_string()),
        ..EpisodeMetadata::default()
    };
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .create(std::io::BufWriter::new(
            std::fs::File::create(path).unwrap(),
        ))
        .unwrap();
    w.write_metadata(&mcap::records::Metadata {
        name: scaledp_schema::episode::START_RECORD.into(),
        metadata: meta.start_record(),
    })
    .unwrap();
    let channel = |id: u16, topic: &str, ty: &str| {
        let schema = Arc::new(mcap::Schema {
            id,
            name: ty.into(),
            encoding: "ros2msg".into(),
            data: Cow::Owned(scaledp_schema::msg::definition(ty).unwrap().into_bytes()),
        });
        Arc::new(mcap::Channel {
            id,
            topic: topic.into(),
            schema: Some(schema),
            message_encoding: "cdr".into(),
            metadata: BTreeMap::new(),
        })
    };
    let color = channel(1, "/cam/color", "sensor_msgs/msg/Image");
    let depth = channel(2, "/cam/depth", "sensor_msgs/msg/Image");
    let tf = channel(3, "/tf", "tf2_msgs/msg/TFMessage");
    let tf_static = channel(4, "/tf_static", "tf2_msgs/msg/TFMessage");
    let mut put = |c: &Arc<mcap::Channel<'static>>, t: u64, data: Vec<u8>| {
        w.write(&mcap::Message {
            channel: c.clone(),
            sequence: 0,
            log_time: t,
            publish_time: t,
            data: Cow::Owned(data),
        })
        .unwrap();
    };
    let statics = TfMessage {
        transforms: vec![
            transform(T0, "world", "base_link", 0.0),
            transform(T0, "base_link", "camera_link", 0.25),
        ],
    };
    put(&tf_static, T0, statics.to_cdr());
    for k in 0..5u64 {
        let t = T0 + k * 33_333_333;
        let header = Header {
            stamp: Time::from_ns(t),
            frame_id: "camera_color_optical_frame".into(),
        };
        let rgb = Image {
            header: header.clone(),
            height: 6,
            width: 8,
            encoding: "rgb8".into(),
            is_bigendian: 0,
            step: 24,
            data: vec![k as u8 * 40; 8 * 6 * 3],
        };
        let mm: Vec<u16> = (0..48u16)
            .map(|i| if i % 7 == 0 { 0 } else { 1000 + i })
            .collect();
        let d = Image {
            encoding: "16UC1".into(),
            step: 16,
            data: mm.iter().flat_map(|v| v.to_le_bytes()).collect(),
            ..rgb.clone()
        };
        put(&color, t, rgb.to_cdr());
        put(&depth, t, d.to_cdr());
        if k < 3 {
            let moving = TfMessage {
                transforms: vec![transform(t, "base_link", "gripper", 0.1 * k as f64)],
            };
            put(&tf, t, moving.to_cdr());
        }
    }
    w.finish().unwrap();
}

#[test]
fn depth_images_and_tf_frames_reach_the_rrd() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = dir.path().join("episode_000000.mcap");
    write(&mcap);
    let rrd = dir.path().join("out.rrd");
    view(
        &[mcap.display().to_string()],
        ViewOptions::new(),
        &Target::Save(rrd.clone()),
    )
    .unwrap();
    let v = run_python("read_rrd.py", &[&rrd]);
    let rec = &v["recordings"][0]["entities"];
    let depth = &rec["/depth/cam"];
    let rows = depth["rows"].as_array().unwrap();
    let frames: Vec<&serde_json::Value> = rows
        .iter()
        .filter(|r| r.get("DepthImage:buffer").is_some())
        .collect();
    assert_eq!(frames.len(), 5, "{depth}");
    assert_eq!(frames[0]["DepthImage:meter"], 1000.0, "{}", frames[0]);
    assert_eq!(frames[0]["DepthImage:buffer"]["bytes"], 8 * 6 * 2);
    // tf: the static tree and its root tied to the scene, the moving frame per message.
    let camera = &rec["/world/tf/camera_link"]["static"];
    assert_eq!(camera["Transform3D:child_frame"], "camera_link", "{camera}");
    assert_eq!(camera["Transform3D:parent_frame"], "base_link");
    assert_eq!(
        camera["Transform3D:translation"],
        serde_json::json!([0.25, 0.0, 0.5])
    );
    let root = &rec["/world/tf/world"]["static"];
    assert_eq!(root["Transform3D:parent_frame"], "tf#/world", "{root}");
    let moving = rec["/world/tf/gripper"]["rows"].as_array().unwrap();
    let moves: Vec<&serde_json::Value> = moving
        .iter()
        .filter(|r| r.get("Transform3D:translation").is_some())
        .collect();
    assert_eq!(moves.len(), 3, "{moving:?}");
    assert!(moves.iter().all(|r| r["capture_time"].as_i64().is_some()));
}
