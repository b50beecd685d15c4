//! The engine against the candle modules and candle's autograd, on tiny models with random
//! weights (no zero anywhere): the same loss, every gradient, the same DDIM samples.

use candle_core::{Device, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::Engine;
use crate::config::{Architecture, Attention, ModelConfig, ModelSize};
use crate::inference::ddim_sample;
use crate::model::{Crop, ScaleDp};
use crate::scheduler::NoiseScheduler;
use crate::trainer::{candle_loss_and_grads, loss_and_grads, LossSpec, Phases};

fn tiny(attention: Attention) -> ModelConfig {
    let cams = vec![
        "observation.images.front".into(),
        "observation.images.wrist".into(),
    ];
    let mut c = ModelConfig::new(ModelSize::Ti, cams, (26, 22), 4, 3);
    c.size = None;
    c.depth = 2;
    c.hidden = 32;
    c.heads = 4;
    c.action_chunk = 6;
    c.resnet_width = 16;
    c.keypoints = 5;
    c.feature_dim = 7;
    c.attention = attention;
    c
}

/// A tiny DP-T on the same inputs (3 layers, to reach a middle layer's every path).
fn tiny_dpt(attention: Attention, dropout: f64) -> ModelConfig {
    let mut c = tiny(attention);
    (c.arch, c.depth, c.dropout) = (Architecture::DpT, 3, dropout);
    c
}

fn max_rel(a: &Tensor, b: &Tensor) -> f32 {
    let d = (a - b)
        .and_then(|d| d.abs())
        .and_then(|d| d.max_all())
        .and_then(|d| d.to_scalar::<f32>());
    let s = b
        .abs()
        .and_then(|d| d.max_all())
        .and_then(|d| d.to_scalar::<f32>());
    match (d, s) {
        (Ok(d), Ok(s)) => d / s.max(1e-6),
        _ => f32::INFINITY,
    }
}

/// Loss and every gradient, engine vs autograd, for one configuration.
fn compare(cfg: ModelConfig, spec: LossSpec, micro: Option<usize>) {
    let attention = cfg.attention;
    let dev = Device::Cpu;
    let (model, params) = ScaleDp::fresh(&cfg, 3, &dev).unwrap();
    // Random weights everywhere (the fresh adaLN-Zero init would zero most gradients).
    let model_r = ScaleDp::random(&cfg, 3, 0.2, &dev).unwrap();
    for (p, (_, t)) in params.iter().zip(model_r.weights()) {
        p.var.set(t).unwrap();
    }
    let sched = NoiseScheduler::new(100).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut batch = crate::bench::synthetic_batch(&cfg, 5, &mut rng);
    // Some padded steps at the end of two samples.
    for s in [1usize, 3] {
        for k in 4..6 {
            batch.action_is_pad[s * 6 + k] = true;
        }
    }
    let (mut r1, mut r2) = (ChaCha8Rng::seed_from_u64(9), ChaCha8Rng::seed_from_u64(9));
    let (l1, g1) = candle_loss_and_grads(
        &model,
        &sched,
        &params,
        &batch,
        spec,
        micro,
        &mut r1,
        &mut Phases::default(),
    )
    .unwrap();
    let mut engine = Engine::default();
    let (l2, g2) = loss_and_grads(
        &model,
        &mut engine,
        &sched,
        &params,
        &batch,
        spec,
        micro,
        &mut r2,
        &mut Phases::default(),
    )
    .unwrap();
    assert!(
        (l1 - l2).abs() <= 1e-5 * l1.abs().max(1.0),
        "loss {l1} vs {l2}"
    );
    let mut checked = 0;
    for ((p, a), b) in params.iter().zip(&g1).zip(&g2) {
        match (a, b) {
            (Some(a), Some(b)) => {
                let r = max_rel(b, a);
                assert!(
                    r < 2e-3,
                    "{}: gradient differs by {r} of its largest value ({attention:?}, {spec:?})",
                    p.name
                );
                checked += 1;
            }
            (None, None) => {}
            _ => panic!("{}: a gradient on one side only", p.name),
        }
    }
    assert_eq!(checked, params.len(), "every parameter gets a gradient");
    // Both consumed the same draws.
    assert_eq!(
        rand::Rng::random::<u64>(&mut r1),
        rand::Rng::random::<u64>(&mut r2)
    );
}

#[test]
fn loss_and_every_gradient_match_candles_autograd() {
    compare(tiny(Attention::NonCausal), LossSpec::default(), None);
}

#[test]
fn causal_masked_several_noise_draws_and_micro_batches_match_too() {
    let spec = LossSpec {
        noise_samples: 3,
        mask_padding: true,
    };
    compare(tiny(Attention::Causal), spec, Some(2));
}

#[test]
fn dpt_loss_and_every_gradient_match_candles_autograd() {
    compare(tiny_dpt(Attention::Causal, 0.0), LossSpec::default(), None);
}

#[test]
fn dpt_non_causal_several_noise_draws_and_micro_batches_match_too() {
    let spec = LossSpec {
        noise_samples: 2,
        mask_padding: true,
    };
    compare(tiny_dpt(Attention::NonCausal, 0.0), spec, Some(3));
}

/// With dropout on, both paths draw the same masks in the same order from the step's generator:
/// the same loss and gradients, which a mask applied in the wrong place would change.
#[test]
fn dpt_dropout_draws_the_same_masks_in_both_paths() {
    let spec = LossSpec {
        noise_samples: 2,
        mask_padding: false,
    };
    compare(tiny_dpt(Attention::Causal, 0.3), spec, Some(3));
}

#[test]
fn ddim_samples_match_the_candle_path() {
    ddim_matches(tiny(Attention::NonCausal));
}

/// DP-T's samples too, and dropout (configured at 0.3) is off at inference: DDIM draws the
/// noise and nothing else, so both paths agree.
#[test]
fn dpt_ddim_samples_match_the_candle_path() {
    ddim_matches(tiny_dpt(Attention::Causal, 0.3));
}

fn ddim_matches(cfg: ModelConfig) {
    let dev = Device::Cpu;
    let model = ScaleDp::random(&cfg, 4, 0.2, &dev).unwrap();
    let mut sched = NoiseScheduler::new(100).unwrap();
    sched.set_timesteps(10).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let batch = crate::bench::synthetic_batch(&cfg, 3, &mut rng);
    let (mut r1, mut r2) = (ChaCha8Rng::seed_from_u64(2), ChaCha8Rng::seed_from_u64(2));
    let cond = model
        .encode(&batch.images, &batch.state, 3, Crop::Center, &mut r1)
        .unwrap();
    let want = ddim_sample(&model, &sched, &cond, &mut r1).unwrap();
    let got = Engine::default()
        .sample(&model, &sched, &batch.images, &batch.state, 3, &mut r2)
        .unwrap();
    let got = Tensor::from_vec(got, want.dims(), &dev).unwrap();
    let d = (&got - &want)
        .unwrap()
        .abs()
        .unwrap()
        .max_all()
        .unwrap()
        .to_scalar::<f32>()
        .unwrap();
    assert!(d < 1e-4, "samples differ by {d}");
}

/// Padded action steps count in the loss unless masked (diffusion_policy and LeRobot train on
/// them; they repeat the episode's last action).
#[test]
fn padded_steps_are_trained_on_unless_masked() {
    let cfg = tiny(Attention::NonCausal);
    let dev = Device::Cpu;
    let (model, params) = ScaleDp::fresh(&cfg, 3, &dev).unwrap();
    let sched = NoiseScheduler::new(100).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut batch = crate::bench::synthetic_batch(&cfg, 2, &mut rng);
    batch.action_is_pad.iter_mut().for_each(|p| *p = true);
    for mask_padding in [false, true] {
        let spec = LossSpec {
            noise_samples: 1,
            mask_padding,
        };
        let mut r = ChaCha8Rng::seed_from_u64(1);
        let (loss, grads) = loss_and_grads(
            &model,
            &mut Engine::default(),
            &sched,
            &params,
            &batch,
            spec,
            None,
            &mut r,
            &mut Phases::default(),
        )
        .unwrap();
        let moved = grads.iter().flatten().any(|g| {
            g.abs()
                .unwrap()
                .max_all()
                .unwrap()
                .to_scalar::<f32>()
                .unwrap()
                > 0.0
        });
        if mask_padding {
            assert_eq!(loss, 0.0);
            assert!(!moved, "masked: no gradient");
        } else {
            assert!(loss > 0.1, "all-padded batch still trains: loss {loss}");
            assert!(moved);
        }
    }
}

#[test]
fn the_rational_tanh_is_within_half_a_millionth_of_tanh() {
    let mut worst = (0f64, 0f32);
    // Every 1/4096 over [−12, 12], the tiny range's edges and the clamp's.
    let edges = [4e-4f32, -4e-4, 3.9e-4, 7.998_811_7, 8.0, -8.0, 0.0];
    let grid = (-12 * 4096..=12 * 4096).map(|i| i as f32 / 4096.0);
    for x in grid.chain(edges) {
        let err = (f64::from(super::ops::tanh(x)) - f64::from(x).tanh()).abs();
        if err > worst.0 {
            worst = (err, x);
        }
    }
    assert!(worst.0 < 5e-7, "|error| {} at x = {}", worst.0, worst.1);
    assert!(super::ops::tanh(f32::NAN).is_nan());
    for (x, want) in [(f32::INFINITY, 1.0), (f32::NEG_INFINITY, -1.0), (1e30, 1.0)] {
        assert!((super::ops::tanh(x) - want).abs() < 5e-7, "tanh({x})");
    }
}
