//! The schedule, learning rate and EMA against their formulas, computed here independently in
//! f64 (diffusers' DDIMScheduler with squaredcos_cap_v2, leading spacing, set_alpha_to_one).

use candle_core::{Device, Tensor};
use scaledp_policy::{cosine_lr, EmaConfig, NoiseScheduler};

/// ᾱ(t) = cos²((t + 0.008) / 1.008 · π/2).
fn alpha_bar(t: f64) -> f64 {
    ((t + 0.008) / 1.008 * std::f64::consts::PI / 2.0)
        .cos()
        .powi(2)
}

#[test]
fn alphas_cumprod_follow_the_capped_cosine_schedule() -> scaledp_policy::Result<()> {
    let s = NoiseScheduler::new(100)?;
    let mut prod = 1.0f64;
    for i in 0..100 {
        let beta =
            (1.0 - alpha_bar((i + 1) as f64 / 100.0) / alpha_bar(i as f64 / 100.0)).min(0.999);
        prod *= 1.0 - beta;
        let got = f64::from(s.alphas_cumprod()[i]);
        assert!(
            (got - prod).abs() <= 1e-6 * prod.max(1e-3),
            "ᾱ[{i}] = {got}, formula {prod}"
        );
        assert!((f64::from(s.betas()[i]) - beta).abs() < 1e-7);
    }
    // Only the last beta reaches the cap, as in diffusers.
    assert_eq!(s.betas()[99], 0.999);
    assert!(s.betas()[98] < 0.999);
    Ok(())
}

#[test]
fn ddim_uses_leading_timesteps_and_the_eta_zero_update() -> scaledp_policy::Result<()> {
    let mut s = NoiseScheduler::new(100)?;
    s.set_timesteps(10)?;
    assert_eq!(s.timesteps(), &[90, 80, 70, 60, 50, 40, 30, 20, 10, 0]);
    let dev = Device::Cpu;
    let x = Tensor::new(&[[0.3f32, -0.7, 2.5]], &dev)?;
    let eps = Tensor::new(&[[0.1f32, 0.4, -1.2]], &dev)?;
    let ab = |t: usize| {
        let mut p = 1.0;
        for i in 0..=t {
            p *= 1.0
                - (1.0 - alpha_bar((i + 1) as f64 / 100.0) / alpha_bar(i as f64 / 100.0))
                    .min(0.999);
        }
        p
    };
    for (t, prev) in [(50usize, Some(40usize)), (0, None)] {
        let got = s.step(&eps, t, &x)?.flatten_all()?.to_vec1::<f32>()?;
        let (a, ap) = (ab(t), prev.map_or(1.0, ab));
        for k in 0..3 {
            let (xv, e) = (
                f64::from([0.3f32, -0.7, 2.5][k]),
                f64::from([0.1f32, 0.4, -1.2][k]),
            );
            let x0 = ((xv - (1.0 - a).sqrt() * e) / a.sqrt()).clamp(-1.0, 1.0);
            let want = ap.sqrt() * x0 + (1.0 - ap).sqrt() * e;
            assert!(
                (f64::from(got[k]) - want).abs() < 1e-5,
                "t {t}: {} vs {want}",
                got[k]
            );
        }
    }
    let noisy = s
        .add_noise(&x, &eps, &[30])?
        .flatten_all()?
        .to_vec1::<f32>()?;
    let a = ab(30);
    let want = a.sqrt() * 0.3 + (1.0 - a).sqrt() * 0.1;
    assert!((f64::from(noisy[0]) - want).abs() < 1e-6);
    Ok(())
}

#[test]
fn learning_rate_warms_up_linearly_then_follows_half_a_cosine() {
    // diffusers: lr(0) = 0; peak at the end of the warm-up; 0 at the last step.
    assert_eq!(cosine_lr(1e-4, 0, 500, 10_000), 0.0);
    assert!((cosine_lr(1e-4, 250, 500, 10_000) - 0.5e-4).abs() < 1e-12);
    assert!((cosine_lr(1e-4, 500, 500, 10_000) - 1e-4).abs() < 1e-12);
    let mid = 500 + (10_000 - 500) / 2;
    assert!((cosine_lr(1e-4, mid, 500, 10_000) - 0.5e-4).abs() < 1e-9);
    assert!(cosine_lr(1e-4, 10_000, 500, 10_000).abs() < 1e-12);
}

#[test]
fn ema_decay_is_diffusion_policys() {
    let e = EmaConfig::default();
    // The first two updates copy the weights; then 1 − (1 + k)^−0.75 with k = step − 1.
    assert_eq!(e.decay(0), 0.0);
    assert_eq!(e.decay(1), 0.0);
    assert!((e.decay(2) - (1.0 - 2f64.powf(-0.75))).abs() < 1e-12);
    assert!((e.decay(1001) - (1.0 - 1001f64.powf(-0.75))).abs() < 1e-12);
    assert_eq!(e.decay(100_000_000), 0.9999);
}
