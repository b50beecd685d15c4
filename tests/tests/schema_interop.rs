//! Our ros2msg texts and CDR bytes against what Python `rosbags` (rosbag2's conventions) makes.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use scaledp_schema::msg::{
    CameraInfo, CompressedImage, Header, Image, JointState, Point, Pose, PoseStamped, Quaternion,
    RegionOfInterest, TfMessage, Time, Transform, TransformStamped, Vector3,
};
use scaledp_schema::{CdrWriter, RosMessage};
use scaledp_tests::run_python;

fn header() -> Header {
    Header {
        stamp: Time {
            sec: 1_700_000_000,
            nanosec: 123_456_789,
        },
        frame_id: "zed_front_camera_optical_frame".into(),
    }
}

fn encode<M: RosMessage>(m: &M, big_endian: bool) -> Vec<u8> {
    let mut w = CdrWriter::with_capacity(64, big_endian);
    m.write(&mut w);
    w.finish()
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

fn check<M: RosMessage + PartialEq + std::fmt::Debug>(
    reference: &serde_json::Value,
    name: &str,
    m: M,
) {
    for (order, be) in [("le", false), ("be", true)] {
        let want = reference["cdr"][name][order].as_str().unwrap();
        // rosbags pads to a multiple of 4; the padding carries nothing, compare the body.
        let ours = encode(&m, be);
        assert_eq!(hex(&ours), want[..ours.len() * 2], "{name} {order}");
        assert!(
            want[ours.len() * 2..].chars().all(|c| c == '0'),
            "{name} {order}: trailing bytes"
        );
        let back = M::from_cdr(&unhex(want)).unwrap();
        assert_eq!(back, m, "{name} {order} decode");
    }
}

#[test]
fn definitions_and_cdr_match_rosbags() {
    let reference = run_python("ros_reference.py", &[]);
    let defs = reference["definitions"].as_object().unwrap();
    assert_eq!(defs.len(), 11);
    for (type_name, text) in defs {
        let ours = scaledp_schema::msg::definition(type_name)
            .unwrap_or_else(|| panic!("no definition of {type_name}"));
        assert_eq!(ours, text.as_str().unwrap(), "{type_name}");
    }
    assert_eq!(
        Image::definition(),
        defs["sensor_msgs/msg/Image"].as_str().unwrap()
    );

    check(
        &reference,
        "image",
        Image {
            header: header(),
            height: 2,
            width: 3,
            encoding: "bgra8".into(),
            is_bigendian: 0,
            step: 12,
            data: (0..24).collect(),
        },
    );
    check(
        &reference,
        "compressed",
        CompressedImage {
            header: header(),
            format: "jpeg".into(),
            data: vec![255, 216, 255, 217],
        },
    );
    check(
        &reference,
        "joint_state",
        JointState {
            header: header(),
            name: vec!["fr3_joint1".into(), "fr3_joint2".into(), "j".into()],
            position: vec![0.5, -1.25, 3.0],
            velocity: vec![0.0, 0.1, -0.2],
            effort: vec![],
        },
    );
    let h = std::f64::consts::FRAC_1_SQRT_2;
    check(
        &reference,
        "pose_stamped",
        PoseStamped {
            header: header(),
            pose: Pose {
                position: Point {
                    x: 0.1,
                    y: -0.2,
                    z: 0.3,
                },
                orientation: Quaternion {
                    x: 0.0,
                    y: 0.0,
                    z: h,
                    w: h,
                },
            },
        },
    );
    let mut info = CameraInfo::pinhole(header(), 640, 480, 600.5, 320.0, 240.0);
    info.d = vec![0.1, -0.2, 0.0, 0.001, 0.05];
    info.binning_x = 2;
    info.roi = RegionOfInterest {
        x_offset: 1,
        y_offset: 2,
        height: 3,
        width: 4,
        do_rectify: true,
    };
    check(&reference, "camera_info", info);
    check(
        &reference,
        "tf",
        TfMessage {
            transforms: vec![
                TransformStamped {
                    header: header(),
                    child_frame_id: "fr3_link0".into(),
                    transform: Transform {
                        translation: Vector3 {
                            x: 0.25,
                            y: -0.5,
                            z: 2.0,
                        },
                        rotation: Quaternion {
                            x: 0.0,
                            y: 0.0,
                            z: h,
                            w: h,
                        },
                    },
                },
                TransformStamped {
                    header: Header {
                        stamp: Time { sec: 1, nanosec: 2 },
                        frame_id: String::new(),
                    },
                    child_frame_id: "cam".into(),
                    transform: Transform::default(),
                },
            ],
        },
    );
}
