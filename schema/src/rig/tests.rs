//! Unit tests of rig files: the shipped rigs, and what a bad one is told.

use super::*;

#[test]
fn shipped_rigs_parse() {
    for name in Rig::builtin_names() {
        let rig = Rig::builtin(name).unwrap_or_else(|| panic!("{name} must parse"));
        assert!(!rig.topics().is_empty());
    }
    let franka = Rig::builtin("franka_2zed").unwrap();
    assert_eq!(franka.cameras.len(), 2);
    assert_eq!(franka.cameras[0].encoding(), "bgra8");
    let ur = Rig::builtin("bimanual_ur5_3rs").unwrap();
    assert_eq!((ur.arms.len(), ur.cameras.len()), (2, 3));
    assert_eq!(ur.cameras[0].encoding(), "rgb8");
    assert!(Rig::builtin_names().any(|n| n == "franka_2zed_v4"));
}

/// The real rigs record what their drivers publish beside colour, under the drivers' own
/// names: realsense2_camera 4.x, the ZED wrapper v5 and v4.
#[test]
fn shipped_real_rigs_match_the_drivers_names() {
    let line = |rig: &str| -> Vec<(String, TopicKind, String)> {
        let rig = Rig::builtin(rig).unwrap();
        let beside = rig.recorded_beside();
        beside
            .into_iter()
            .filter(|t| t.owner == rig.cameras[0].name || t.owner.is_empty())
            .map(|t| {
                let encoding = match t.kind {
                    TopicKind::Depth => rig.cameras[0].depth.as_ref().unwrap().encoding.as_str(),
                    _ => "",
                };
                (t.topic, t.kind, encoding.to_string())
            })
            .collect()
    };
    let k = |t: &str, kind, e: &str| (t.to_string(), kind, e.to_string());
    let tf = [
        k("/tf", TopicKind::Tf, ""),
        k("/tf_static", TopicKind::TfStatic, ""),
    ];
    let rs = "/cam_high/camera/";
    assert_eq!(
        line("bimanual_ur5_3rs"),
        [
            k(
                &format!("{rs}aligned_depth_to_color/image_raw"),
                TopicKind::Depth,
                "16UC1"
            ),
            k(&format!("{rs}color/camera_info"), TopicKind::CameraInfo, ""),
            k(
                &format!("{rs}aligned_depth_to_color/camera_info"),
                TopicKind::CameraInfo,
                ""
            ),
        ]
        .into_iter()
        .chain(tf.clone())
        .collect::<Vec<_>>()
    );
    let zed = "/zed_front/zed_node/";
    for (rig, color, info) in [
        (
            "franka_2zed",
            "rgb/color/rect/image",
            "rgb/color/rect/camera_info",
        ),
        ("franka_2zed_v4", "rgb/image_rect_color", "rgb/camera_info"),
    ] {
        assert_eq!(
            Rig::builtin(rig).unwrap().cameras[0].topic,
            format!("{zed}{color}")
        );
        assert_eq!(
            line(rig),
            [
                k(
                    &format!("{zed}depth/depth_registered"),
                    TopicKind::Depth,
                    "32FC1"
                ),
                k(&format!("{zed}{info}"), TopicKind::CameraInfo, ""),
                k(
                    &format!("{zed}depth/camera_info"),
                    TopicKind::CameraInfo,
                    ""
                ),
            ]
            .into_iter()
            .chain(tf.clone())
            .collect::<Vec<_>>(),
            "{rig}"
        );
    }
}

#[test]
fn video_cameras_carry_compressed_video() {
    use crate::msg::{CompressedVideo, Time};
    use crate::RosMessage;
    let text = include_str!("../../../rigs/franka_sim.toml").replacen(
        "fps = 30.0",
        "fps = 30.0\nencoding = \"h264\"",
        1,
    );
    let rig = Rig::parse(&text, Path::new("h264.toml")).unwrap();
    assert_eq!(rig.cameras[0].video_codec(), Some("h264"));
    assert_eq!(
        rig.cameras[0].message_type(),
        "foxglove_msgs/msg/CompressedVideo"
    );
    assert_eq!(rig.cameras[1].message_type(), "sensor_msgs/msg/Image");
    let both = text.replacen(
        "encoding = \"h264\"",
        "encoding = \"h264\"\ncompressed = true",
        1,
    );
    let e = Rig::parse(&both, Path::new("both.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("camera 'front'") && e.contains("h264"), "{e}");
    // The message: its stamp reads like a header's, and it survives a round trip.
    let m = CompressedVideo {
        timestamp: Time { sec: 3, nanosec: 7 },
        frame_id: "front".into(),
        data: vec![0, 0, 0, 1, 0x67],
        format: "h264".into(),
    };
    let cdr = m.to_cdr();
    assert_eq!(CompressedVideo::from_cdr(&cdr).unwrap(), m);
    assert_eq!(crate::msg::header_stamp(&cdr).unwrap(), m.timestamp);
    let def = CompressedVideo::definition();
    assert!(
        def.starts_with("builtin_interfaces/Time timestamp\nstring frame_id"),
        "{def}"
    );
    assert!(def.contains("MSG: builtin_interfaces/Time"), "{def}");
}

#[test]
fn errors_name_the_file_and_the_problem() {
    let text = include_str!("../../../rigs/franka_2zed.toml").replace("\"fr3_joint7\"", "");
    let e = Rig::parse(&text, Path::new("my_rig.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("my_rig.toml: arm 'arm': model fr3 has 7 joints"),
        "{e}"
    );
    let e = Rig::parse("name = 3", Path::new("x.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("x.toml: "), "{e}");
}

#[test]
fn command_topics_come_last_with_their_types() {
    // The real rigs know no command topics; their simulated cells add one per arm and
    // gripper, after every state topic, so existing topic indices keep their meaning. The real
    // rigs' training streams (what comes before depth, camera_info and tf) are the cells'.
    for (real, sim) in [
        ("franka_2zed", "franka_sim"),
        ("bimanual_ur5_3rs", "bimanual_ur5_sim"),
    ] {
        let (real, sim) = (Rig::builtin(real).unwrap(), Rig::builtin(sim).unwrap());
        assert!(real.command_topics().is_empty());
        assert!(sim.recorded_beside().is_empty(), "{}", sim.name);
        let n = real.topics().len() - real.recorded_beside().len();
        let topics = sim.topics();
        assert_eq!(topics.len(), n + 2 * sim.arms.len());
        for (a, b) in real.topics().iter().zip(&topics).take(n) {
            assert_eq!((&a.topic, &a.message_type), (&b.topic, &b.message_type));
        }
        assert_eq!(&topics[n..], sim.command_topics().as_slice());
        for pair in topics[n..].chunks(2) {
            assert_eq!(pair[0].message_type, "geometry_msgs/msg/PoseStamped");
            assert_eq!(pair[1].message_type, "sensor_msgs/msg/JointState");
            assert_eq!(pair[0].rate_hz, sim.control_rate_hz);
        }
    }
    let leader = include_str!("../../../rigs/franka_sim.toml").replace(
        "command_topic = \"/cartesian_motion_controller/target_frame\"",
        "command_topic = \"/leader/joint_states\"\ncommand_type = \"joint_state\"",
    );
    let rig = Rig::parse(&leader, Path::new("leader.toml")).unwrap();
    assert_eq!(rig.arms[0].command_type, Some(CommandType::JointState));
    assert_eq!(
        rig.command_topics()[0].message_type,
        "sensor_msgs/msg/JointState"
    );
    // A command topic may not reuse a state topic.
    let clash = include_str!("../../../rigs/franka_sim.toml").replace(
        "/leader/franka_gripper/joint_states",
        "/franka_gripper/joint_states",
    );
    assert!(Rig::parse(&clash, Path::new("clash.toml")).is_err());
}

#[test]
fn gripper_width_round_trips() {
    for m in [
        GripperModel::FrankaHand,
        GripperModel::Robotiq2f85,
        GripperModel::MetaworldSawyer,
        GripperModel::AlohaViperx,
    ] {
        let q = m.positions_for_width(0.05, 2);
        assert!(
            (m.width_m(&q[..if m == GripperModel::Robotiq2f85 { 1 } else { 2 }]) - 0.05).abs()
                < 1e-12
        );
    }
    // MetaWorld: both pads open at 0.094 m, closed fingers (r 0.04, l −0.03) at 0.024 m.
    let mw = GripperModel::MetaworldSawyer;
    assert!((mw.width_m(&[0.0, 0.0]) - 0.094).abs() < 1e-12);
    assert!((mw.width_m(&[0.04, -0.03]) - 0.024).abs() < 1e-12);
    // ALOHA: fingers at gym-aloha's open position (0.058 m each) are 0.116 m apart.
    let aloha = GripperModel::AlohaViperx;
    assert!((aloha.width_m(&[0.058, -0.058]) - aloha.max_width_m()).abs() < 1e-12);
}

/// A camera's depth and `camera_info`, `/tf`, `/tf_static` and further topics are topics of
/// the rig, after the training streams (whose indices stay as they were), each with its kind,
/// owner and whether it is latched.
#[test]
fn what_is_recorded_beside_the_training_streams() {
    // The simulated cell (the shipped real rig already lists all of these).
    let base = include_str!("../../../rigs/bimanual_ur5_sim.toml");
    let n = Rig::parse(base, Path::new("base.toml"))
        .unwrap()
        .topics()
        .len();
    let text = base.replacen(
        "fps = 30.0",
        "fps = 30.0\ncamera_info_topic = \"/cam_high/camera/color/camera_info\"\n\
         depth = { topic = \"/cam_high/camera/aligned_depth_to_color/image_raw\", encoding = \"16UC1\" }",
        1,
    ) + "\n[tf]\nrate_hz = 100.0\n\n[[topic]]\nname = \"/diagnostics\"\ntype = \"diagnostic_msgs/msg/DiagnosticArray\"\n";
    let rig = Rig::parse(&text, Path::new("rs.toml")).unwrap();
    let topics = rig.topics();
    let beside: Vec<(&str, TopicKind, &str, bool, f64)> = topics[n..]
        .iter()
        .map(|t| {
            (
                t.topic.as_str(),
                t.kind,
                t.owner.as_str(),
                t.latched,
                t.rate_hz,
            )
        })
        .collect();
    assert_eq!(
        beside,
        [
            (
                "/cam_high/camera/aligned_depth_to_color/image_raw",
                TopicKind::Depth,
                "high",
                false,
                30.0
            ),
            (
                "/cam_high/camera/color/camera_info",
                TopicKind::CameraInfo,
                "high",
                false,
                30.0
            ),
            ("/tf", TopicKind::Tf, "", false, 100.0),
            ("/tf_static", TopicKind::TfStatic, "", true, 0.0),
            ("/diagnostics", TopicKind::Extra, "", false, 0.0),
        ]
    );
    assert_eq!(topics[n].message_type, "sensor_msgs/msg/Image");
    assert!(topics[n].is_image);
    // Cut to its training streams, the rig lists those and nothing beside them.
    assert_eq!(rig.clone().training_streams().topics(), topics[..n]);
    let small = rig.clone().with_image_size(32, 24);
    assert!(small
        .cameras
        .iter()
        .all(|c| (c.width, c.height) == (32, 24)));
    assert_eq!(small.topics().len(), topics.len());
    assert_eq!(
        rig.cameras[0].depth.as_ref().map(|d| d.encoding),
        Some(DepthEncoding::U16Millimetres)
    );
    // What a bad one is told.
    for (edit, want) in [
        (
            text.replace("encoding = \"16UC1\"", "encoding = \"mono8\""),
            "unknown variant `mono8`",
        ),
        (
            text.replace("diagnostic_msgs/msg/DiagnosticArray", "DiagnosticArray"),
            "is not a full ROS 2 type",
        ),
        (
            text.replace("name = \"/diagnostics\"", "name = \"/tf\""),
            "'/tf' is used twice",
        ),
    ] {
        let e = Rig::parse(&edit, Path::new("bad.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains(want) && e.contains("bad.toml"), "{e}");
    }
}
