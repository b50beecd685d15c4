//! `RobotModel` forward kinematics and `pose6_from_transform` against an independent numpy
//! implementation of the DH tables (tests/py/fk_reference.py): the flange of every built-in
//! model and the pose the converter writes (`pose6_from_transform(base_from_flange(q) ·
//! default_flange_from_tcp())`: the Franka Hand TCP for FR3/Panda, tool0 for UR5/UR5e), as
//! x, y, z, roll, pitch, yaw with R = Rz(yaw)·Ry(pitch)·Rx(roll), at random joint positions
//! within the limits and at (and next to) gimbal lock.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI, TAU};
use std::io::Write;
use std::process::{Command, Stdio};

use scaledp_schema::kinematics::{pose6_from_transform, RobotModel};
use scaledp_tests::{python, workspace};

/// Metres for positions, radians for angles, and the largest element difference of two
/// rotation matrices.
const TOL: f64 = 1e-6;

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

    fn between(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
}

/// Which frame of the arm is compared.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Frame {
    /// The last DH frame (`fr3_link8`, UR `tool0`).
    Flange,
    /// What the converter outputs for a rig without `tcp_xyz_rpy` or URDF: the flange times
    /// the model's `default_flange_from_tcp` (Franka Hand TCP; tool0 for UR).
    Tcp,
}

/// A 3×3 rotation matrix, rows first.
type Mat3 = [[f64; 3]; 3];

/// One answer of the Python reference: the pose and its rotation matrix.
type Reference = ([f64; 6], Mat3);

/// Poses of `frame` from the Python reference for `model` at each of `qs`.
fn reference(model: RobotModel, frame: Frame, qs: &[Vec<f64>]) -> Vec<Reference> {
    let script = workspace().join("tests/py/fk_reference.py");
    let mut child = Command::new(python())
        .arg(&script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("running {}: {e}", script.display()));
    let frame = match frame {
        Frame::Flange => "flange",
        Frame::Tcp => "tcp",
    };
    let request = serde_json::json!({ "model": model.to_string(), "frame": frame, "q": qs });
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
    let want: Vec<Reference> =
        serde_json::from_slice(&out.stdout).expect("fk_reference.py printed no pose list");
    assert_eq!(want.len(), qs.len(), "one reference pose per joint vector");
    want
}

/// `a − b` wrapped into [−π, π).
fn angle_diff(a: f64, b: f64) -> f64 {
    (a - b + PI).rem_euclid(TAU) - PI
}

/// Rz(yaw)·Ry(pitch)·Rx(roll), written out (no project code).
fn matrix_from_rpy(roll: f64, pitch: f64, yaw: f64) -> Mat3 {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sy, cy) = yaw.sin_cos();
    [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
}

fn max_diff(a: &Mat3, b: &Mat3) -> f64 {
    let mut m = 0.0f64;
    for (ra, rb) in a.iter().zip(b) {
        for (x, y) in ra.iter().zip(rb) {
            m = m.max((x - y).abs());
        }
    }
    m
}

/// The pose the code under test gives for `frame`, and the rotation of its transform.
fn pose(model: RobotModel, frame: Frame, q: &[f64]) -> ([f64; 6], Mat3) {
    let mut t = model.base_from_flange(q).expect("valid q");
    if frame == Frame::Tcp {
        t *= model.default_flange_from_tcp();
    }
    let cols = [t.x_axis, t.y_axis, t.z_axis];
    let r = std::array::from_fn(|row| std::array::from_fn(|col| cols[col][row]));
    (pose6_from_transform(t), r)
}

/// Worst differences seen by [`compare`].
#[derive(Debug, Default)]
struct Worst {
    position: f64,
    rpy: f64,
    rotation: f64,
    /// Poses whose roll/pitch/yaw were compared one by one (away from gimbal lock).
    rpy_compared: usize,
}

/// Compares the Rust pose of `frame` with the numpy reference at every `qs`: position and
/// the rotation rebuilt from the Rust roll/pitch/yaw always, the angles themselves (wrapped
/// into ±π) where the reference's cos(pitch) leaves them well defined.
fn compare(model: RobotModel, frame: Frame, qs: &[Vec<f64>]) -> Worst {
    let want = reference(model, frame, qs);
    let mut worst = Worst::default();
    for (q, (want, want_r)) in qs.iter().zip(&want) {
        let (got, got_r) = pose(model, frame, q);
        let context = || format!("{model} {frame:?} q {q:?}\nrust  {got:?}\nnumpy {want:?}");
        for k in 0..3 {
            let d = (got[k] - want[k]).abs();
            assert!(d <= TOL, "position {k} differs by {d:e} m: {}", context());
            worst.position = worst.position.max(d);
        }
        // The transform itself, before any angle extraction.
        let d = max_diff(&got_r, want_r);
        assert!(d <= TOL, "rotation differs by {d:e}: {}", context());
        // Roll, pitch and yaw must describe that rotation under R = Rz·Ry·Rx.
        let d = max_diff(&matrix_from_rpy(got[3], got[4], got[5]), want_r);
        assert!(
            d <= TOL,
            "Rz(yaw)·Ry(pitch)·Rx(roll) of the Rust angles differs by {d:e} from the numpy \
             rotation: {}",
            context()
        );
        worst.rotation = worst.rotation.max(d);
        // Away from gimbal lock the angles are unique (up to 2π): compare them directly.
        if want_r[0][0].hypot(want_r[1][0]) > 1e-4 {
            for k in 3..6 {
                let d = angle_diff(got[k], want[k]).abs();
                assert!(d <= TOL, "angle {k} differs by {d:e} rad: {}", context());
                worst.rpy = worst.rpy.max(d);
            }
            worst.rpy_compared += 1;
        }
    }
    eprintln!(
        "{model} {frame:?}: {} poses, worst position {:e} m, angle {:e} rad ({} compared), \
         rotation {:e}",
        qs.len(),
        worst.position,
        worst.rpy,
        worst.rpy_compared,
        worst.rotation
    );
    worst
}

/// `n` seeded joint vectors within `model`'s limits, led by both limit corners.
fn random_qs(model: RobotModel, seed: u64, n: usize) -> Vec<Vec<f64>> {
    let limits = model.joint_limits();
    assert_eq!(limits.len(), model.dof());
    let mut rng = Lcg(seed);
    let mut qs = vec![
        limits.iter().map(|l| l.0).collect::<Vec<_>>(),
        limits.iter().map(|l| l.1).collect(),
    ];
    qs.extend((2..n).map(|_| limits.iter().map(|&(lo, hi)| rng.between(lo, hi)).collect()));
    qs
}

fn check(model: RobotModel, frame: Frame, seed: u64) {
    let qs = random_qs(model, seed, 200);
    let worst = compare(model, frame, &qs);
    // Random joint vectors essentially never land within 1e-4 of gimbal lock.
    assert!(
        worst.rpy_compared >= qs.len() - 2,
        "{model}: only {} of {} poses had their angles compared",
        worst.rpy_compared,
        qs.len()
    );
}

#[test]
fn fr3_flange_poses_match_numpy_dh() {
    check(RobotModel::Fr3, Frame::Flange, 7);
}

#[test]
fn panda_flange_poses_match_numpy_dh() {
    check(RobotModel::Panda, Frame::Flange, 11);
}

#[test]
fn ur5_flange_poses_match_numpy_dh() {
    check(RobotModel::Ur5, Frame::Flange, 5);
}

#[test]
fn ur5e_flange_poses_match_numpy_dh() {
    check(RobotModel::Ur5e, Frame::Flange, 13);
}

#[test]
fn fr3_hand_tcp_poses_match_numpy() {
    check(RobotModel::Fr3, Frame::Tcp, 17);
}

#[test]
fn panda_hand_tcp_poses_match_numpy() {
    check(RobotModel::Panda, Frame::Tcp, 19);
}

#[test]
fn ur5_tool0_poses_match_numpy() {
    check(RobotModel::Ur5, Frame::Tcp, 23);
}

#[test]
fn ur5e_tool0_poses_match_numpy() {
    check(RobotModel::Ur5e, Frame::Tcp, 29);
}

/// Joint vectors whose TCP x axis is vertical (pitch = ±π/2: roll and yaw are not unique),
/// and the same turned by `δ` about the TCP z axis (the last joint), which tilts the x axis
/// by `δ` off vertical with roll = ±π/2: the worst case for a gimbal-lock shortcut.
/// Returns (δ, q) pairs.
fn near_gimbal_lock(model: RobotModel, seed: u64) -> Vec<(f64, Vec<f64>)> {
    const DELTAS: [f64; 10] = [
        0.0, 1e-12, 1e-9, 1e-7, 5e-7, 1e-6, 1.2e-6, 1.4e-6, 1e-5, 1e-3,
    ];
    let mut rng = Lcg(seed);
    let mut qs = Vec::new();
    for i in 0..8 {
        let side = if i % 2 == 0 { 1.0 } else { -1.0 };
        let q = match model {
            // x of the hand vertical: q2 = q3 = 0, q4 = −π/2, q5 = ±π/2, q7 = −π/4; q1 and
            // q6 free (within both FR3's and Panda's limits).
            RobotModel::Fr3 | RobotModel::Panda => vec![
                rng.between(-2.7, 2.7),
                0.0,
                0.0,
                -FRAC_PI_2,
                side * FRAC_PI_2,
                rng.between(0.6, 3.7),
                -FRAC_PI_4,
            ],
            // tool0 x vertical: q2 + q3 + q4 = 0, q6 = ±π/2; q1 and q5 free.
            RobotModel::Ur5 | RobotModel::Ur5e => {
                let (b, c) = (rng.between(-PI, PI), rng.between(-PI, PI));
                vec![
                    rng.between(-TAU, TAU),
                    b,
                    c,
                    -b - c,
                    rng.between(-TAU, TAU),
                    side * FRAC_PI_2,
                ]
            }
            // The benchmarks' arms are checked against their simulators (sim/tests/bridge.rs).
            RobotModel::Sawyer | RobotModel::Vx300s => unreachable!("not a DH model"),
        };
        for d in DELTAS {
            for d in [d, -d] {
                let mut q = q.clone();
                *q.last_mut().unwrap() += d;
                qs.push((d, q));
            }
        }
    }
    qs
}

#[test]
fn converter_poses_match_numpy_at_and_near_gimbal_lock() {
    for (model, seed) in [
        (RobotModel::Fr3, 31),
        (RobotModel::Panda, 37),
        (RobotModel::Ur5, 41),
        (RobotModel::Ur5e, 43),
    ] {
        let (deltas, qs): (Vec<f64>, Vec<Vec<f64>>) =
            near_gimbal_lock(model, seed).into_iter().unzip();
        for ((d, q), (_, r)) in deltas
            .iter()
            .zip(&qs)
            .zip(reference(model, Frame::Tcp, &qs))
        {
            let limits = model.joint_limits();
            assert!(
                q.iter().zip(limits).all(|(x, l)| (l.0..=l.1).contains(x)),
                "{model} {q:?} is outside the joint limits"
            );
            // The x axis is δ off vertical: r20 = ±cos δ, cos(pitch) = |sin δ|.
            let tilt = r[0][0].hypot(r[1][0]);
            assert!(
                (tilt - d.sin().abs()).abs() < 1e-12,
                "{model} {q:?}: x axis {tilt:e} rad off vertical, not δ = {d:e}"
            );
        }
        compare(model, Frame::Tcp, &qs);
    }
}

#[test]
fn hand_tcp_is_0_1034_m_beyond_the_flange_turned_minus_45_degrees() {
    // The Franka Hand TCP against the flange, both from numpy: 0.1034 m along the flange z,
    // x turned −45° about it.
    for model in [RobotModel::Fr3, RobotModel::Panda] {
        let qs = random_qs(model, 47, 20);
        let flange = reference(model, Frame::Flange, &qs);
        for (q, ((f, fr), (t, tr))) in
            qs.iter()
                .zip(flange.iter().zip(reference(model, Frame::Tcp, &qs)))
        {
            for k in 0..3 {
                let d = t[k] - f[k] - 0.1034 * fr[k][2];
                assert!(d.abs() < 1e-12, "{model} {q:?}: axis {k} off by {d:e}");
            }
            let (s, c) = (-FRAC_PI_4).sin_cos();
            for k in 0..3 {
                let x = fr[k][0] * c + fr[k][1] * s;
                assert!((tr[k][0] - x).abs() < 1e-12 && (tr[k][2] - fr[k][2]).abs() < 1e-12);
            }
        }
    }
}

#[test]
fn angle_diff_wraps() {
    assert!((angle_diff(PI - 1e-9, -PI + 1e-9) + 2e-9).abs() < 1e-12);
    assert!((angle_diff(0.5, 0.25) - 0.25).abs() < 1e-15);
}

#[test]
fn matrix_from_rpy_is_rz_ry_rx() {
    // A quarter turn of each alone, checked on where the axes go.
    let r = matrix_from_rpy(FRAC_PI_2, 0.0, 0.0); // Rx: y → z
    assert!((r[2][1] - 1.0).abs() < 1e-15);
    let r = matrix_from_rpy(0.0, FRAC_PI_2, 0.0); // Ry: z → x
    assert!((r[0][2] - 1.0).abs() < 1e-15);
    let r = matrix_from_rpy(0.0, 0.0, FRAC_PI_2); // Rz: x → y
    assert!((r[1][0] - 1.0).abs() < 1e-15);
    // Order: roll first (fixed axes).
    let r = matrix_from_rpy(FRAC_PI_2, 0.0, FRAC_PI_2);
    // Rx(π/2) maps z to −y, then Rz(π/2) maps −y to +x.
    assert!((r[0][2] - 1.0).abs() < 1e-15, "{r:?}");
}
