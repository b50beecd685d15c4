//! Every message round-trips in both byte orders, and no prefix or corruption of a payload
//! panics or allocates: it is an error.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use scaledp_schema::msg::{
    CompressedImage, Header, Image, JointState, Point, Pose, PoseStamped, Quaternion, Time,
};
use scaledp_schema::{CdrWriter, RosMessage};

fn header() -> Header {
    Header {
        stamp: Time::from_ns(1_700_000_000_987_654_321),
        frame_id: "fr3_link0".into(),
    }
}

fn both_orders<M: RosMessage + PartialEq + std::fmt::Debug>(m: &M) -> [Vec<u8>; 2] {
    [false, true].map(|be| {
        let mut w = CdrWriter::with_capacity(0, be);
        m.write(&mut w);
        let bytes = w.finish();
        assert_eq!(
            &M::from_cdr(&bytes).unwrap(),
            m,
            "round trip, big endian = {be}"
        );
        bytes
    })
}

fn hostile<M: RosMessage>(bytes: &[u8]) {
    for cut in 0..bytes.len() {
        assert!(
            M::from_cdr(&bytes[..cut]).is_err(),
            "{} prefix of {cut} bytes decoded",
            M::TYPE_NAME
        );
    }
    // Every 4-byte window set to 0xFFFFFFFF: lengths become huge, values garbage; never a panic.
    for at in 4..bytes.len().saturating_sub(4) {
        let mut b = bytes.to_vec();
        b[at..at + 4].copy_from_slice(&[0xFF; 4]);
        let _ = M::from_cdr(&b);
    }
}

#[test]
fn messages_round_trip_and_survive_hostile_input() {
    let image = Image {
        header: header(),
        height: 2,
        width: 2,
        encoding: "rgb8".into(),
        is_bigendian: 0,
        step: 8, // padded rows: step > width × 3
        data: (0..16).collect(),
    };
    let js = JointState {
        header: header(),
        name: (1..=7).map(|i| format!("fr3_joint{i}")).collect(),
        position: vec![0.1, -0.2, 0.3, -2.0, 0.0, 1.9, 0.78],
        velocity: vec![0.0; 7],
        effort: vec![],
    };
    let ci = CompressedImage {
        header: header(),
        format: "jpeg".into(),
        data: vec![0xFF, 0xD8, 0xFF, 0xD9],
    };
    let ps = PoseStamped {
        header: header(),
        pose: Pose {
            position: Point {
                x: 0.3,
                y: 0.0,
                z: 0.5,
            },
            orientation: Quaternion {
                x: 1.0,
                y: 0.0,
                z: 0.0,
                w: 0.0,
            },
        },
    };
    for bytes in both_orders(&image) {
        hostile::<Image>(&bytes);
    }
    for bytes in both_orders(&js) {
        hostile::<JointState>(&bytes);
    }
    for bytes in both_orders(&ci) {
        hostile::<CompressedImage>(&bytes);
    }
    for bytes in both_orders(&ps) {
        hostile::<PoseStamped>(&bytes);
    }
    assert_eq!(Time::from_ns(header().stamp.as_ns()), header().stamp);
    assert_eq!(
        scaledp_schema::msg::header_stamp(&js.to_cdr()).unwrap(),
        header().stamp
    );
}
