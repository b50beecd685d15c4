//! Damped-least-squares inverse kinematics on the schema crate's forward kinematics: one
//! control tick of a Cartesian position controller, as a robot's driver runs it at its joint
//! rate.
//!
//! Each tick turns the TCP's pose error into a twist (a first-order approach with time constant
//! [`IkParams::time_constant_s`], capped in speed), maps it to joint velocities through
//! `Jᵀ(JJᵀ + λ²I)⁻¹` (plus, on redundant arms, a pull towards a rest posture in the Jacobian's
//! null space), scales them uniformly so no joint exceeds its velocity limit (the direction of
//! motion is kept), integrates, and clamps to the joint position limits.

use glam::{DMat3, DMat4, DQuat, DVec3};
use scaledp_schema::RobotModel;

/// Most joints of any supported arm.
pub const MAX_DOF: usize = 7;

/// Joint velocity limits (rad/s) from the makers' data sheets: FR3 and Panda (franka_description),
/// UR5 (CB3: 180°/s on every joint), UR5e (180°/s on the base, shoulder and elbow, 360°/s on
/// the wrists).
pub fn velocity_limits(model: RobotModel) -> &'static [f64] {
    const FR3: [f64; 7] = [2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26];
    const PANDA: [f64; 7] = [2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61];
    use std::f64::consts::{PI, TAU};
    const UR5: [f64; 6] = [PI; 6];
    const UR5E: [f64; 6] = [PI, PI, PI, TAU, TAU, TAU];
    // Sawyer: Rethink's data sheet; ViperX 300: Dynamixel XM540/XM430 at 12 V, about π rad/s.
    const SAWYER: [f64; 7] = [1.74, 1.328, 1.957, 1.957, 3.485, 3.485, 4.545];
    const VX300S: [f64; 6] = [PI; 6];
    match model {
        RobotModel::Fr3 => &FR3,
        RobotModel::Panda => &PANDA,
        RobotModel::Ur5 => &UR5,
        RobotModel::Ur5e => &UR5E,
        RobotModel::Sawyer => &SAWYER,
        RobotModel::Vx300s => &VX300S,
    }
}

/// Tuning of the controller; `Default` gives what the simulator uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkParams {
    /// Damping λ of the least-squares solve (m, rad).
    pub damping: f64,
    /// Time constant (s) of the approach to the target: the twist is error / time constant
    /// (never faster than one tick).
    pub time_constant_s: f64,
    /// Largest TCP speed (m/s).
    pub max_linear_speed_mps: f64,
    /// Largest TCP angular speed (rad/s).
    pub max_angular_speed_rps: f64,
    /// Gain (1/s) of the null-space pull towards the rest posture (redundant arms only).
    pub nullspace_gain: f64,
    /// Distance (rad) kept from each joint position limit.
    pub limit_margin_rad: f64,
}

impl Default for IkParams {
    /// λ 0.01, τ 30 ms, 1 m/s, 2 rad/s, null-space gain 1/s, 0.02 rad from the limits.
    fn default() -> Self {
        Self {
            damping: 0.01,
            time_constant_s: 0.03,
            max_linear_speed_mps: 1.0,
            max_angular_speed_rps: 2.0,
            nullspace_gain: 1.0,
            limit_margin_rad: 0.02,
        }
    }
}

/// The pose error `target` − `current` as (position error, rotation vector), both in the base
/// frame.
pub fn pose_error(current: &DMat4, target: &DMat4) -> (DVec3, DVec3) {
    let dp = target.w_axis.truncate() - current.w_axis.truncate();
    let rc = DQuat::from_mat3(&DMat3::from_mat4(*current)).normalize();
    let rt = DQuat::from_mat3(&DMat3::from_mat4(*target)).normalize();
    let mut dq = rt * rc.conjugate();
    if dq.w < 0.0 {
        dq = -dq;
    }
    // 2·atan2(|v|, w) keeps full precision near zero, where acos(w) loses half the digits.
    let v = dq.xyz();
    let s = v.length();
    let rot = if s > 1e-300 && s.is_finite() {
        v * (2.0 * s.atan2(dq.w) / s)
    } else {
        DVec3::ZERO
    };
    (dp, rot)
}

/// Geometric Jacobian (6 × dof: linear rows then angular rows, base frame) of the point
/// `base_from_tcp`'s origin, from the model's DH frames. `None` when `q` is invalid.
pub fn jacobian(model: RobotModel, q: &[f64], tcp: DVec3) -> Option<[[f64; MAX_DOF]; 6]> {
    let frames = model.frames(q).ok()?;
    let mut j = [[0.0; MAX_DOF]; 6];
    for i in 0..model.dof() {
        // Modified DH (Franka): joint i turns about z of its own frame. Standard DH (UR): about
        // z of the frame before it (the base for the first joint).
        let (origin, z) = match model {
            RobotModel::Fr3 | RobotModel::Panda => {
                (frames[i].w_axis.truncate(), frames[i].z_axis.truncate())
            }
            RobotModel::Ur5 | RobotModel::Ur5e => {
                let f = if i == 0 {
                    DMat4::IDENTITY
                } else {
                    frames[i - 1]
                };
                (f.w_axis.truncate(), f.z_axis.truncate())
            }
            // Chains from MJCF models: joint i turns about its own axis in its own frame.
            RobotModel::Sawyer | RobotModel::Vx300s => model.joint_axis(i, &frames)?,
        };
        let lin = z.cross(tcp - origin);
        for (r, v) in [lin.x, lin.y, lin.z, z.x, z.y, z.z].into_iter().enumerate() {
            j[r][i] = v;
        }
    }
    Some(j)
}

/// Solves `a x = b` for a symmetric positive definite 6 × 6 `a` (Cholesky).
fn solve_spd6(mut a: [[f64; 6]; 6], b: [f64; 6]) -> Option<[f64; 6]> {
    for k in 0..6 {
        let d = a[k][k] - (0..k).map(|m| a[k][m] * a[k][m]).sum::<f64>();
        if d.is_nan() || d <= 0.0 {
            return None;
        }
        a[k][k] = d.sqrt();
        for i in k + 1..6 {
            let s = a[i][k] - (0..k).map(|m| a[i][m] * a[k][m]).sum::<f64>();
            a[i][k] = s / a[k][k];
        }
    }
    let mut y = [0.0; 6];
    for i in 0..6 {
        y[i] = (b[i] - (0..i).map(|m| a[i][m] * y[m]).sum::<f64>()) / a[i][i];
    }
    let mut x = [0.0; 6];
    for i in (0..6).rev() {
        x[i] = (y[i] - (i + 1..6).map(|m| a[m][i] * x[m]).sum::<f64>()) / a[i][i];
    }
    Some(x)
}

/// `Jᵀ(JJᵀ + λ²I)⁻¹ v` for the first `n` columns of `j`.
fn dls(j: &[[f64; MAX_DOF]; 6], n: usize, lambda: f64, v: [f64; 6]) -> Option<[f64; MAX_DOF]> {
    let mut a = [[0.0; 6]; 6];
    for (r, row) in a.iter_mut().enumerate() {
        for (c, x) in row.iter_mut().enumerate() {
            *x = (0..n).map(|k| j[r][k] * j[c][k]).sum::<f64>();
        }
        row[r] += lambda * lambda;
    }
    let y = solve_spd6(a, v)?;
    let mut out = [0.0; MAX_DOF];
    for (k, o) in out.iter_mut().enumerate().take(n) {
        *o = (0..6).map(|r| j[r][k] * y[r]).sum();
    }
    Some(out)
}

/// One control tick of `dt_s`: moves `q` (and sets `qd`) towards the joint positions that put
/// the TCP (`base_from_flange · flange_from_tcp`) at `target` (`base_from_tcp`). `rest` is the
/// posture a redundant arm drifts towards. Returns false (and holds still) when the Jacobian
/// solve fails.
#[allow(clippy::too_many_arguments)]
pub fn track(
    model: RobotModel,
    flange_from_tcp: &DMat4,
    target: &DMat4,
    rest: &[f64],
    params: &IkParams,
    dt_s: f64,
    q: &mut [f64],
    qd: &mut [f64],
) -> bool {
    let n = model.dof();
    let Ok(flange) = model.base_from_flange(q) else {
        qd.iter_mut().for_each(|v| *v = 0.0);
        return false;
    };
    let tcp = flange * *flange_from_tcp;
    let (mut dp, mut dr) = pose_error(&tcp, target);
    if dp.length() < 1e-12 && dr.length() < 1e-12 {
        // At the target: hold exactly (rounding must not make a resting arm creep).
        (dp, dr) = (DVec3::ZERO, DVec3::ZERO);
    }
    let gain = 1.0 / params.time_constant_s.max(dt_s);
    let (mut lin, mut ang) = (dp * gain, dr * gain);
    let scale = (lin.length() / params.max_linear_speed_mps)
        .max(ang.length() / params.max_angular_speed_rps)
        .max(1.0);
    lin /= scale;
    ang /= scale;
    let Some(j) = jacobian(model, q, tcp.w_axis.truncate()) else {
        return false;
    };
    let v = [lin.x, lin.y, lin.z, ang.x, ang.y, ang.z];
    let Some(mut v_q) = dls(&j, n, params.damping, v) else {
        qd.iter_mut().for_each(|v| *v = 0.0);
        return false;
    };
    if n > 6 && params.nullspace_gain > 0.0 {
        // z − J⁺(J z): the part of the posture pull that leaves the TCP where it is.
        let mut z = [0.0; MAX_DOF];
        for k in 0..n {
            z[k] = params.nullspace_gain * (rest[k] - q[k]);
        }
        let mut jz = [0.0; 6];
        for (r, x) in jz.iter_mut().enumerate() {
            *x = (0..n).map(|k| j[r][k] * z[k]).sum();
        }
        if let Some(back) = dls(&j, n, params.damping, jz) {
            for k in 0..n {
                v_q[k] += z[k] - back[k];
            }
        }
    }
    let limits = velocity_limits(model);
    let over = (0..n).map(|k| v_q[k].abs() / limits[k]).fold(1.0, f64::max);
    for (k, (lo, hi)) in model.joint_limits().iter().enumerate() {
        let next = (q[k] + v_q[k] / over * dt_s)
            .clamp(lo + params.limit_margin_rad, hi - params.limit_margin_rad);
        qd[k] = (next - q[k]) / dt_s;
        q[k] = next;
    }
    true
}

/// Joint positions reaching `target` from `seed` (repeated ticks of [`track`] without speed
/// limits to speak of), and the remaining (position, rotation) error.
pub fn solve(
    model: RobotModel,
    flange_from_tcp: &DMat4,
    target: &DMat4,
    seed: &[f64],
    iterations: usize,
) -> (Vec<f64>, f64, f64) {
    let mut params = IkParams {
        time_constant_s: 0.0,
        max_linear_speed_mps: 0.5,
        max_angular_speed_rps: 1.0,
        ..IkParams::default()
    };
    let mut q = seed.to_vec();
    let mut qd = vec![0.0; q.len()];
    for i in 0..iterations {
        // The damped null-space pull leaks a little into the task: the last half goes without.
        if i == iterations / 2 {
            params.nullspace_gain = 0.0;
        }
        if !track(
            model,
            flange_from_tcp,
            target,
            seed,
            &params,
            0.01,
            &mut q,
            &mut qd,
        ) {
            break;
        }
    }
    let reached = model
        .base_from_flange(&q)
        .map(|f| f * *flange_from_tcp)
        .unwrap_or(DMat4::IDENTITY);
    let (dp, dr) = pose_error(&reached, target);
    (q, dp.length(), dr.length())
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    const MODELS: [RobotModel; 4] = [
        RobotModel::Fr3,
        RobotModel::Panda,
        RobotModel::Ur5,
        RobotModel::Ur5e,
    ];

    fn home(model: RobotModel) -> Vec<f64> {
        match model {
            RobotModel::Fr3 | RobotModel::Panda => vec![0.0, -0.6, 0.0, -2.3, 0.0, 1.7, 0.8],
            RobotModel::Ur5 | RobotModel::Ur5e => vec![0.0, -1.9, 1.9, -1.57, -1.57, 0.0],
            RobotModel::Sawyer => vec![1.89, -0.58, -0.98, 1.64, 0.94, 1.04, 2.29],
            RobotModel::Vx300s => vec![0.0, -0.96, 1.16, 0.0, -0.3, 0.0],
        }
    }

    #[test]
    fn the_jacobian_matches_finite_differences() {
        // The benchmarks' MJCF chains too (their axes come from the chain, not a DH rule).
        for model in MODELS
            .into_iter()
            .chain([RobotModel::Sawyer, RobotModel::Vx300s])
        {
            let q = home(model);
            let tcp = model.default_flange_from_tcp();
            let fk = |q: &[f64]| model.base_from_flange(q).unwrap() * tcp;
            let p0 = fk(&q);
            let j = jacobian(model, &q, p0.w_axis.truncate()).unwrap();
            let h = 1e-6;
            for k in 0..model.dof() {
                let mut qh = q.clone();
                qh[k] += h;
                let (dp, dr) = pose_error(&p0, &fk(&qh));
                let num = [dp.x, dp.y, dp.z, dr.x, dr.y, dr.z].map(|x| x / h);
                for r in 0..6 {
                    assert!(
                        (num[r] - j[r][k]).abs() < 1e-5,
                        "{model} joint {k} row {r}: {} vs {}",
                        num[r],
                        j[r][k]
                    );
                }
            }
        }
    }

    #[test]
    fn tracking_reaches_random_reachable_poses_within_a_millimetre_and_a_hundredth_radian() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for model in MODELS {
            let tcp = model.default_flange_from_tcp();
            let limits = velocity_limits(model);
            for trial in 0..6 {
                // A reachable target: the pose of a posture up to 0.5 rad from home per joint.
                let goal_q: Vec<f64> = home(model)
                    .iter()
                    .zip(model.joint_limits())
                    .map(|(h, (lo, hi))| {
                        (h + rng.random_range(-0.5..0.5)).clamp(lo + 0.1, hi - 0.1)
                    })
                    .collect();
                let target = model.base_from_flange(&goal_q).unwrap() * tcp;
                let (mut q, mut qd) = (home(model), vec![0.0; model.dof()]);
                let dt = 0.002;
                let params = IkParams::default();
                for _ in 0..1500 {
                    let before = q.clone();
                    assert!(track(
                        model,
                        &tcp,
                        &target,
                        &home(model),
                        &params,
                        dt,
                        &mut q,
                        &mut qd
                    ));
                    for k in 0..model.dof() {
                        let speed = (q[k] - before[k]).abs() / dt;
                        assert!(
                            speed <= limits[k] * (1.0 + 1e-9),
                            "{model}: joint {k} at {speed} rad/s"
                        );
                    }
                }
                let reached = model.base_from_flange(&q).unwrap() * tcp;
                let (dp, dr) = pose_error(&reached, &target);
                assert!(
                    dp.length() < 1e-3 && dr.length() < 1e-2,
                    "{model} trial {trial}: {:.2} mm, {:.4} rad off",
                    dp.length() * 1e3,
                    dr.length()
                );
            }
        }
    }

    #[test]
    fn a_far_target_is_approached_at_the_velocity_limits_and_within_the_position_limits() {
        for model in MODELS {
            let tcp = model.default_flange_from_tcp();
            let limits = velocity_limits(model);
            let start = home(model);
            let here = model.base_from_flange(&start).unwrap() * tcp;
            // 40 cm sideways and a quarter turn about the vertical: far more than one tick.
            let target = DMat4::from_translation(DVec3::new(0.0, 0.4, 0.0))
                * here
                * DMat4::from_rotation_z(1.5);
            let (mut q, mut qd) = (start.clone(), vec![0.0; model.dof()]);
            let dt = 0.001;
            // TCP speed caps high enough that the joints' limits bind.
            let fast = IkParams {
                max_linear_speed_mps: 20.0,
                max_angular_speed_rps: 40.0,
                ..IkParams::default()
            };
            let mut fastest: f64 = 0.0;
            for _ in 0..300 {
                let before = q.clone();
                track(model, &tcp, &target, &start, &fast, dt, &mut q, &mut qd);
                for (k, (lo, hi)) in model.joint_limits().iter().enumerate() {
                    let ratio = (q[k] - before[k]).abs() / dt / limits[k];
                    assert!(
                        ratio <= 1.0 + 1e-9,
                        "{model}: joint {k} at {ratio} × its limit"
                    );
                    assert!(
                        (*lo..=*hi).contains(&q[k]),
                        "{model}: joint {k} at {}",
                        q[k]
                    );
                    fastest = fastest.max(ratio);
                }
            }
            assert!(
                fastest > 0.99,
                "{model}: never at a velocity limit ({fastest})"
            );
        }
    }

    #[test]
    fn solve_finds_postures_for_poses_and_refuses_nothing_silently() {
        for model in MODELS {
            let tcp = model.default_flange_from_tcp();
            let start = home(model);
            let here = model.base_from_flange(&start).unwrap() * tcp;
            let target = DMat4::from_translation(DVec3::new(0.05, -0.05, -0.1)) * here;
            let (q, dp, dr) = solve(model, &tcp, &target, &start, 400);
            assert!(dp < 1e-6 && dr < 1e-6, "{model}: {dp} m, {dr} rad");
            assert_ne!(q, start);
        }
    }
}
