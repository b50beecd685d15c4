//! A recording with registered depth and `camera_info`, written message by message through the
//! recorder's episode writer, so the tests know every value that was "published": a RealSense
//! camera `wrist` (rgb8, raw 16UC1 depth in mm, both camera_infos 64×48) and a ZED camera
//! `front` (bgra8, 32FC1 depth over image_transport's `compressedDepth`, a camera_info of
//! another resolution), a Franka arm and gripper. Frames are captured every 1/30 s, depth at
//! the same instants as colour, each frame's values a function of its index `k`. Each episode
//! is labelled `success` by operator [`OPERATOR`] and carries a recorder's verdict record.

use std::path::Path;

use scaledp_recorder::{EpisodeOptions, VERDICT_RECORD};
use scaledp_schema::msg::{CameraInfo, CompressedImage, Header, Image, JointState, Time};
use scaledp_schema::{EpisodeMetadata, Label, Rig, RosMessage};

/// Recorded colour, depth and camera_info size.
pub const W: u32 = 64;
/// Recorded height.
pub const H: u32 = 48;
/// `compressedDepth`'s quantisation (the publisher's defaults, z0 = 100, depth_max = 10 m).
pub const A: f32 = 100.0 * 101.0;
/// B = 1 − A / depth_max.
pub const B: f32 = 1.0 - A / 10.0;
/// The task, operator and recorder's verdict line the episodes store (labelled `success`).
pub const TASK: &str = "look at the depth";
/// See [`TASK`].
pub const OPERATOR: &str = "ana";
/// See [`TASK`].
pub const VERDICT_LINE: &str = "accepted: 2.9 of 3.0 s kept (the recorder's line)";
/// First capture (ns).
pub const T0: u64 = 1_800_000_000_000_000_000;
const FRAME_NS: f64 = 1e9 / 30.0;

/// The rig of `w × h` cameras; `wrist_depth` is the wrist depth's declared encoding.
pub fn rig_sized(wrist_depth: &str, (w, h): (u32, u32)) -> Rig {
    let text = format!(
        r#"
name = "depth_rig"
control_rate_hz = 10.0

[[arm]]
name = "arm"
model = "fr3"
joint_state_topic = "/franka/joint_states"
joint_names = ["fr3_joint1", "fr3_joint2", "fr3_joint3", "fr3_joint4", "fr3_joint5", "fr3_joint6", "fr3_joint7"]
rate_hz = 100.0

[arm.gripper]
model = "franka_hand"
topic = "/franka_gripper/joint_states"
joint_names = ["fr3_finger_joint1", "fr3_finger_joint2"]
rate_hz = 50.0

[[camera]]
name = "wrist"
topic = "/camera/color/image_raw"
model = "realsense"
width = {w}
height = {h}
fps = 30.0
camera_info_topic = "/camera/color/camera_info"

[camera.depth]
topic = "/camera/aligned_depth_to_color/image_raw"
encoding = "{wrist_depth}"
camera_info_topic = "/camera/aligned_depth_to_color/camera_info"

[[camera]]
name = "front"
topic = "/zed/zed_node/rgb/color/rect/image"
model = "zed"
width = {w}
height = {h}
fps = 30.0
camera_info_topic = "/zed/zed_node/rgb/color/rect/camera_info"

[camera.depth]
topic = "/zed/zed_node/depth/depth_registered/compressedDepth"
encoding = "32FC1"
compressed = true
"#
    );
    Rig::parse(&text, Path::new("depth_rig.toml")).expect("the test rig")
}

/// The rig of the 64×48 recording.
pub fn rig(wrist_depth: &str) -> Rig {
    rig_sized(wrist_depth, (W, H))
}

/// Wrist depth of frame `k` at (x, y), mm; 0 (a hole) on every ninth diagonal.
pub fn wrist_mm(k: u64, x: u32, y: u32) -> u16 {
    if (u64::from(x) + 2 * u64::from(y) + k) % 9 == 0 {
        0
    } else {
        (500 + 40 * k + 3 * u64::from(x) + u64::from(y)) as u16
    }
}

/// Front quantised inverse depth of frame `k` at (x, y); 0 (a hole) on every 13th diagonal.
pub fn front_q(k: u64, x: u32, y: u32) -> u16 {
    if (3 * u64::from(x) + u64::from(y) + k) % 13 == 0 {
        0
    } else {
        (3000 + 17 * k + 5 * u64::from(x) + 2 * u64::from(y)) as u16
    }
}

/// What image_transport's subscriber makes of `q`: metres, NaN for a hole.
pub fn front_m(q: u16) -> f32 {
    if q == 0 {
        f32::NAN
    } else {
        A / (f32::from(q) - B)
    }
}

/// The colour frames' grey level of frame `k` (a flat image survives JPEG within a level).
pub fn colour_level(k: u64) -> u8 {
    (20 + 2 * k) as u8
}

/// The wrist camera's calibration at `w × h` (60, 61 px focal lengths at 64×48).
pub fn wrist_info(stamp: Time, (w, h): (u32, u32)) -> CameraInfo {
    let s = f64::from(w) / f64::from(W);
    let mut i = CameraInfo::pinhole(
        header(stamp, "camera_color_optical_frame"),
        w,
        h,
        60.0 * s,
        31.5 * s,
        23.75 * s,
    );
    i.k[4] = 61.0 * s;
    i.p[5] = 61.0 * s;
    i.d = vec![0.12, -0.25, 0.001, -0.002, 0.05];
    i
}

fn header(stamp: Time, frame: &str) -> Header {
    Header {
        stamp,
        frame_id: frame.into(),
    }
}

fn compressed_depth(stamp: Time, k: u64, (w, h): (u32, u32)) -> CompressedImage {
    let q: Vec<u16> = (0..h)
        .flat_map(|y| (0..w).map(move |x| front_q(k, x, y)))
        .collect();
    let img = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(w, h, q).expect("a 16-bit image");
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .expect("PNG");
    let mut data = vec![0u8; 4];
    data.extend(A.to_le_bytes());
    data.extend(B.to_le_bytes());
    data.extend(png);
    CompressedImage {
        header: header(stamp, "zed_left_camera_optical_frame"),
        format: "32FC1; compressedDepth png".into(),
        data,
    }
}

/// Writes `seconds` of the 64×48 episode to `path`; the wrist depth in `wrist_depth` (`16UC1`
/// as the rig declares, or `32FC1` for an episode the converter must refuse).
pub fn write(path: &Path, seconds: f64, wrist_depth: &str) {
    write_sized(path, seconds, wrist_depth, (W, H));
}

/// [`write`] with `w × h` images.
pub fn write_sized(path: &Path, seconds: f64, wrist_depth: &str, (w, h): (u32, u32)) {
    let rig = rig_sized("16UC1", (w, h));
    let topics = rig.topics();
    let index = |t: &str| {
        topics
            .iter()
            .position(|s| s.topic == t)
            .expect("a rig topic")
    };
    let meta = EpisodeMetadata {
        task: TASK.into(),
        operator: OPERATOR.into(),
        label: Some(Label::Success),
        rig_name: rig.name.clone(),
        rig_toml: Some(toml::to_string(&rig).expect("rig TOML")),
        ..EpisodeMetadata::default()
    };
    let mut writer = EpisodeOptions::new()
        .create(path, &topics, meta.start_record())
        .expect("an episode file");
    // (log time, topic index, stamp, payload), written in log-time order.
    let mut out: Vec<(u64, usize, u64, Vec<u8>)> = Vec::new();
    let frames = (seconds * 30.0) as u64;
    for k in 0..frames {
        let stamp_ns = T0 + (k as f64 * FRAME_NS).round() as u64;
        let stamp = Time::from_ns(stamp_ns);
        let log = stamp_ns + 30_000_000;
        let level = colour_level(k);
        let rgb = Image {
            header: header(stamp, "camera_color_optical_frame"),
            height: h,
            width: w,
            encoding: "rgb8".into(),
            is_bigendian: 0,
            step: w * 3,
            data: vec![level; (w * h * 3) as usize],
        };
        let bgra = Image {
            encoding: "bgra8".into(),
            step: w * 4,
            data: vec![level; (w * h * 4) as usize],
            ..rgb.clone()
        };
        let mm: Vec<u16> = (0..h)
            .flat_map(|y| (0..w).map(move |x| wrist_mm(k, x, y)))
            .collect();
        let depth = match wrist_depth {
            "16UC1" => Image {
                encoding: "16UC1".into(),
                step: w * 2,
                data: mm.iter().flat_map(|v| v.to_le_bytes()).collect(),
                ..rgb.clone()
            },
            other => Image {
                encoding: other.into(),
                step: w * 4,
                data: mm
                    .iter()
                    .flat_map(|&v| (f32::from(v) / 1000.0).to_le_bytes())
                    .collect(),
                ..rgb.clone()
            },
        };
        let mut far = CameraInfo::pinhole(header(stamp, "zed"), 1280, 720, 700.0, 640.0, 360.0);
        far.d = vec![0.0; 5];
        let mut push =
            |topic: &str, payload: Vec<u8>| out.push((log, index(topic), stamp_ns, payload));
        push("/camera/color/image_raw", rgb.to_cdr());
        push(
            "/camera/color/camera_info",
            wrist_info(stamp, (w, h)).to_cdr(),
        );
        push("/camera/aligned_depth_to_color/image_raw", depth.to_cdr());
        push(
            "/camera/aligned_depth_to_color/camera_info",
            wrist_info(stamp, (w, h)).to_cdr(),
        );
        push("/zed/zed_node/rgb/color/rect/image", bgra.to_cdr());
        push("/zed/zed_node/rgb/color/rect/camera_info", far.to_cdr());
        push(
            "/zed/zed_node/depth/depth_registered/compressedDepth",
            compressed_depth(stamp, k, (w, h)).to_cdr(),
        );
    }
    let arm = &rig.arms[0];
    for j in 0..(seconds * 100.0) as u64 {
        let stamp_ns = T0 + j * 10_000_000;
        let t = j as f64 * 0.01;
        let q: Vec<f64> = (0..7)
            .map(|i| 0.1 * i as f64 + 0.2 * (t + i as f64).sin())
            .collect();
        let js = JointState {
            header: header(Time::from_ns(stamp_ns), ""),
            name: arm.joint_names.clone(),
            position: q,
            velocity: vec![],
            effort: vec![],
        };
        out.push((
            stamp_ns + 500_000,
            index(&arm.joint_state_topic),
            stamp_ns,
            js.to_cdr(),
        ));
        if j % 2 == 0 {
            let g = arm.gripper.as_ref().expect("a gripper");
            let width = 0.02 + 0.01 * t.sin();
            let js = JointState {
                header: header(Time::from_ns(stamp_ns), ""),
                name: g.joint_names.clone(),
                position: vec![width / 2.0, width / 2.0],
                velocity: vec![],
                effort: vec![],
            };
            out.push((stamp_ns + 500_000, index(&g.topic), stamp_ns, js.to_cdr()));
        }
    }
    out.sort_by_key(|m| (m.0, m.1));
    for (log, ti, stamp, payload) in out {
        writer.write(ti, log, stamp, &payload).expect("a message");
    }
    // The recorder's verdict, as `scaledp record` stores it when the episode ends.
    writer
        .write_metadata(
            VERDICT_RECORD,
            [
                ("accepted".to_string(), "true".to_string()),
                ("reason".to_string(), String::new()),
                ("line".to_string(), VERDICT_LINE.to_string()),
            ]
            .into(),
        )
        .expect("the verdict record");
    writer.finish(meta.end_record(), None).expect("the episode");
}
