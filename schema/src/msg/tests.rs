//! Round trips of every message through CDR (both byte orders), and the definitions composed
//! for `sensor_msgs/CameraInfo` and `tf2_msgs/TFMessage` as rosbag2 stores them.

use super::*;
use crate::cdr::CdrWriter;

fn header(frame: &str) -> Header {
    Header {
        stamp: Time {
            sec: 1_700_000_000,
            nanosec: 5,
        },
        frame_id: frame.into(),
    }
}

fn round_trip<M: RosMessage + PartialEq + std::fmt::Debug>(m: &M) {
    for be in [false, true] {
        let mut w = CdrWriter::with_capacity(64, be);
        m.write(&mut w);
        let bytes = w.finish();
        assert_eq!(&M::from_cdr(&bytes).unwrap(), m, "big endian: {be}");
    }
}

fn camera_info() -> CameraInfo {
    let mut info = CameraInfo::pinhole(header("cam_optical"), 640, 480, 600.5, 320.0, 240.0);
    info.d = vec![0.1, -0.2, 0.0, 0.001, 0.05];
    info.binning_x = 2;
    info.roi = RegionOfInterest {
        x_offset: 1,
        y_offset: 2,
        height: 3,
        width: 4,
        do_rectify: true,
    };
    info
}

fn tf() -> TfMessage {
    let t = |parent: &str, child: &str, x: f64| TransformStamped {
        header: header(parent),
        child_frame_id: child.into(),
        transform: Transform {
            translation: Vector3 { x, y: -0.5, z: 2.0 },
            rotation: Quaternion {
                x: 0.0,
                y: 0.0,
                z: std::f64::consts::FRAC_1_SQRT_2,
                w: std::f64::consts::FRAC_1_SQRT_2,
            },
        },
    };
    TfMessage {
        transforms: vec![t("world", "fr3_link0", 0.25), t("fr3_link0", "cam", 1.0)],
    }
}

#[test]
fn camera_info_and_tf_round_trip() {
    round_trip(&camera_info());
    round_trip(&tf());
    round_trip(&TfMessage::default());
    let info = camera_info();
    let cdr = info.to_cdr();
    assert_eq!(camera_info_size(&cdr).unwrap(), (480, 640));
    assert_eq!(header_stamp(&cdr).unwrap(), info.header.stamp);
    // A truncated message is an error, not a panic.
    for n in [0, 5, 40, cdr.len() - 1] {
        assert!(CameraInfo::from_cdr(&cdr[..n]).is_err(), "{n} bytes");
    }
    let tf = tf().to_cdr();
    for n in [4, 12, tf.len() - 3] {
        assert!(TfMessage::from_cdr(&tf[..n]).is_err(), "{n} bytes");
    }
}

#[test]
fn images_show_their_layout_without_their_pixels() {
    let img = Image {
        header: header("depth"),
        height: 2,
        width: 3,
        encoding: "16UC1".into(),
        is_bigendian: 0,
        step: 6,
        data: vec![1; 12],
    };
    round_trip(&img);
    let layout = image_layout(&img.to_cdr()).unwrap();
    assert_eq!(
        layout,
        ImageLayout {
            height: 2,
            width: 3,
            encoding: "16UC1".into()
        }
    );
}

#[test]
fn definitions_are_rosbags_texts() {
    let line = "=".repeat(80);
    let info = definition("sensor_msgs/msg/CameraInfo").unwrap();
    assert_eq!(
        info,
        format!(
            "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\n\
             float64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\n\
             uint32 binning_y\nsensor_msgs/RegionOfInterest roi\n{line}\nMSG: std_msgs/Header\n\
             builtin_interfaces/Time stamp\nstring frame_id\n{line}\nMSG: builtin_interfaces/Time\n\
             int32 sec\nuint32 nanosec\n{line}\nMSG: sensor_msgs/RegionOfInterest\n\
             uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"
        )
    );
    let tf = definition("tf2_msgs/msg/TFMessage").unwrap();
    let sections: Vec<&str> = tf
        .split(&format!("{line}\nMSG: "))
        .skip(1)
        .map(|s| s.lines().next().unwrap())
        .collect();
    assert_eq!(
        sections,
        [
            "geometry_msgs/TransformStamped",
            "std_msgs/Header",
            "builtin_interfaces/Time",
            "geometry_msgs/Transform",
            "geometry_msgs/Vector3",
            "geometry_msgs/Quaternion"
        ]
    );
    assert!(tf.starts_with("geometry_msgs/TransformStamped[] transforms\n"));
    assert_eq!(TfMessage::definition(), tf);
    assert!(known_types().any(|t| t == "tf2_msgs/msg/TFMessage"));
    assert_eq!(known_types().count(), 17);
}

#[test]
fn the_stamp_is_found_from_the_definition() {
    let of = |t: &str| StampField::of_definition(&definition(t).unwrap());
    assert_eq!(of("sensor_msgs/msg/CameraInfo"), StampField::Leading);
    assert_eq!(of("foxglove_msgs/msg/CompressedVideo"), StampField::Leading);
    assert_eq!(of("tf2_msgs/msg/TFMessage"), StampField::FirstElement);
    assert_eq!(of("geometry_msgs/msg/Pose"), StampField::None);
    assert_eq!(StampField::of_definition(""), StampField::None);
    assert_eq!(
        StampField::of_definition("# c\nuint8 A=1\nstd_msgs/Header header\n"),
        StampField::Leading
    );
    let tf = tf();
    assert_eq!(
        StampField::FirstElement.read(&tf.to_cdr()),
        Some(tf.transforms[0].header.stamp)
    );
    assert_eq!(
        StampField::FirstElement.read(&TfMessage::default().to_cdr()),
        None
    );
    assert_eq!(StampField::Leading.read(&[1, 2]), None);
}
