//! `RobotModel` forward kinematics and `pose6_from_transform` against an independent numpy
//! implementation of the DH tables (tests/py/fk_reference.py).

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::f64::consts::{PI, TAU};
use std::io::Write;
use std::process::{Command, Stdio};

use scaledp_schema::kinematics::{pose6_from_transform, RobotModel};
use scaledp_tests::{python, workspace};

/// A tiny seeded generator (64-bit LCG, top 53 bits).
struct Lcg(u64);

impl Lcg {
    fn unit(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Flange poses from the Python reference for `model` ("fr3" or "ur5").
fn reference(model: &str, qs: &[Vec<f64>]) -> Vec<[f64; 6]> {
    let script = workspace().join("tests/py/fk_reference.py");
    let mut child = Command::new(python())
        .arg(&script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("running {}: {e}", script.display()));
    let request = serde_json::json!({ "model": model, "q": qs });
    child
        .stdin
        .take()
        .expect("piped stdin")
        .write_all(request.to_string().as_bytes())
        .expect("writing the request");
    let out = child.wait_with_output().expect("waiting for the reference");
    assert!(
        out.status.success(),
        "fk_reference.py failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("fk_reference.py printed no pose list")
}

/// `a − b` wrapped into [−π, π).
fn angle_diff(a: f64, b: f64) -> f64 {
    (a - b + PI).rem_euclid(TAU) - PI
}

fn check(model: RobotModel, name: &str, seed: u64) {
    let mut rng = Lcg(seed);
    let qs: Vec<Vec<f64>> = (0..50)
        .map(|_| {
            model
                .joint_limits()
                .iter()
                .map(|&(lo, hi)| lo + (hi - lo) * rng.unit())
                .collect()
        })
        .collect();
    let want = reference(name, &qs);
    assert_eq!(want.len(), qs.len());
    let mut worst = [0.0f64; 2];
    for (q, want) in qs.iter().zip(&want) {
        let got = pose6_from_transform(model.base_from_flange(q).expect("valid q"));
        for k in 0..6 {
            let d = if k < 3 {
                got[k] - want[k]
            } else {
                angle_diff(got[k], want[k])
            };
            assert!(
                d.abs() < 1e-6,
                "{model} q {q:?}: component {k} is {} in Rust, {} in numpy\n\
                 rust  {got:?}\nnumpy {want:?}",
                got[k],
                want[k]
            );
            let w = &mut worst[usize::from(k >= 3)];
            *w = w.max(d.abs());
        }
    }
    eprintln!(
        "{model}: worst position {:e} m, angle {:e} rad",
        worst[0], worst[1]
    );
}

#[test]
fn fr3_flange_poses_match_numpy_dh() {
    check(RobotModel::Fr3, "fr3", 7);
}

#[test]
fn ur5_flange_poses_match_numpy_dh() {
    check(RobotModel::Ur5, "ur5", 5);
}

#[test]
fn angle_diff_wraps() {
    assert!((angle_diff(PI - 1e-9, -PI + 1e-9) + 2e-9).abs() < 1e-12);
    assert!((angle_diff(0.5, 0.25) - 0.25).abs() < 1e-15);
}
