//! `UrdfChain` forward kinematics of the DH-equivalent fixtures (tests/fixtures/make_urdf.py)
//! against the built-in `RobotModel` kinematics, plus Euler-angle unwrapping across ±π.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::f64::consts::{PI, TAU};
use std::path::{Path, PathBuf};

use glam::{DMat3, DMat4, DVec3};
use scaledp_converter::Error;
use scaledp_converter::UrdfChain;
use scaledp_schema::kinematics::{pose6_from_transform, unwrap_angles, RobotModel};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/fixtures")
        .join(name)
}

/// A tiny seeded generator (64-bit LCG, top 53 bits) so the test needs no `rand`.
struct Lcg(u64);

impl Lcg {
    fn unit(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    fn q(&mut self, model: RobotModel) -> Vec<f64> {
        model
            .joint_limits()
            .iter()
            .map(|&(lo, hi)| lo + (hi - lo) * self.unit())
            .collect()
    }
}

fn max_rotation_error(a: DMat4, b: DMat4) -> f64 {
    (DMat3::from_mat4(a) - DMat3::from_mat4(b))
        .to_cols_array()
        .iter()
        .fold(0.0, |m, v| m.max(v.abs()))
}

fn check_against_dh(model: RobotModel, file: &str, base: &str, tip: &str, names: &[&str]) {
    let chain = UrdfChain::from_file(&fixture(file), base, tip).expect("fixture chain");
    assert_eq!(chain.joint_names(), names);
    let mut rng = Lcg(0x5eed_0000 + model.dof() as u64);
    let (mut worst_p, mut worst_r) = (0.0f64, 0.0f64);
    for _ in 0..200 {
        let q = rng.q(model);
        let urdf = chain.base_from_tip(&q).expect("URDF FK");
        let dh = model.base_from_flange(&q).expect("DH FK");
        let dp = (urdf.w_axis.truncate() - dh.w_axis.truncate()).length();
        let dr = max_rotation_error(urdf, dh);
        assert!(dp < 1e-9, "{model} q {q:?}: position off by {dp} m");
        assert!(dr < 1e-9, "{model} q {q:?}: rotation off by {dr}");
        worst_p = worst_p.max(dp);
        worst_r = worst_r.max(dr);
    }
    eprintln!("{model}: worst position {worst_p:e} m, rotation {worst_r:e}");
}

#[test]
fn fr3_urdf_matches_modified_dh() {
    let names: Vec<String> = (1..=7).map(|i| format!("fr3_joint{i}")).collect();
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    check_against_dh(
        RobotModel::Fr3,
        "fr3_dh.urdf",
        "fr3_link0",
        "fr3_link8",
        &names,
    );
}

#[test]
fn ur5_urdf_matches_standard_dh() {
    let names = [
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "elbow_joint",
        "wrist_1_joint",
        "wrist_2_joint",
        "wrist_3_joint",
    ];
    check_against_dh(RobotModel::Ur5, "ur5_dh.urdf", "base_link", "tool0", &names);
}

#[test]
fn fixture_errors_name_the_file() {
    let path = fixture("fr3_dh.urdf");
    let shown = path.display().to_string();
    let input_error = |e: Error| match e {
        Error::Input { path: p, reason } => {
            assert_eq!(p, path);
            reason
        }
        other => panic!("expected an input error, got {other}"),
    };
    let e = UrdfChain::from_file(&path, "fr3_link0", "fr3_hand").unwrap_err();
    assert!(e.to_string().starts_with(&shown), "{e}");
    assert!(input_error(e).contains("no link \"fr3_hand\""));
    let e = UrdfChain::from_file(&path, "fr3_link8", "fr3_link0").unwrap_err();
    assert!(input_error(e).contains("not below \"fr3_link8\""));

    let chain = UrdfChain::from_file(&path, "fr3_link0", "fr3_link8").unwrap();
    let e = chain.base_from_tip(&[0.0; 6]).unwrap_err();
    assert!(input_error(e).contains("needs 7 joint positions"));
    let mut q = [0.0, 0.0, 0.0, -1.5, 0.0, 1.5, 0.0];
    q[3] = f64::NAN;
    let e = chain.base_from_tip(&q).unwrap_err();
    assert!(input_error(e).contains("\"fr3_joint4\" is not finite"));

    let missing = fixture("no_such_robot.urdf");
    match UrdfChain::from_file(&missing, "a", "b").unwrap_err() {
        Error::Io { path: p, .. } => assert_eq!(p, missing),
        other => panic!("expected an I/O error, got {other}"),
    }
}

/// Orientation sequences that cross ±π in yaw (rotating about the base z axis) and in roll
/// (rotating about the tool x axis) unwrap into smooth, linear angle tracks.
#[test]
fn rpy_tracks_unwrap_across_pi() {
    let start = RobotModel::Fr3
        .base_from_flange(&[0.3, -0.4, 0.2, -2.0, 0.1, 1.8, 0.7])
        .unwrap();
    let p0 = pose6_from_transform(start);
    let steps = 72;
    // Two full turns so both the +π → −π jump and the way back are exercised.
    let angle = |i: usize| 2.0 * TAU * i as f64 / steps as f64;
    let yaw_turn: Vec<[f64; 6]> = (0..=steps)
        .map(|i| pose6_from_transform(DMat4::from_rotation_z(angle(i)) * start))
        .collect();
    // Turning about the tool's own x axis keeps the tool in place.
    let roll_turn: Vec<[f64; 6]> = (0..=steps)
        .map(|i| pose6_from_transform(start * DMat4::from_rotation_x(-angle(i))))
        .collect();

    for p in &roll_turn {
        let d = DVec3::new(p[0] - p0[0], p[1] - p0[1], p[2] - p0[2]);
        assert!(
            d.length() < 1e-12,
            "rotating in place moved the tool by {d}"
        );
    }
    for (poses, axis, sign) in [(&yaw_turn, 5, 1.0), (&roll_turn, 3, -1.0)] {
        let raw: Vec<f64> = poses.iter().map(|p| p[axis]).collect();
        assert!(
            raw.windows(2).any(|w| (w[1] - w[0]).abs() > PI),
            "the raw track must wrap: {raw:?}"
        );
        for k in 3..6 {
            let mut track: Vec<f64> = poses.iter().map(|p| p[k]).collect();
            unwrap_angles(&mut track);
            for (i, v) in track.iter().enumerate() {
                let want = if k == axis {
                    p0[k] + sign * angle(i)
                } else {
                    p0[k]
                };
                assert!(
                    (v - want).abs() < 1e-9,
                    "angle {k} step {i}: {v} vs {want} ({track:?})"
                );
            }
        }
    }
}
