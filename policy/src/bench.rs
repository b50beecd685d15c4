//! Measurements for `scaledp bench train`: training throughput and the share of step time spent
//! waiting for the loader, the same model in PyTorch from the same initial weights, and DDIM
//! latency per action chunk.

use std::path::{Path, PathBuf};
use std::time::Instant;

use candle_core::Device;
use rand::SeedableRng;

use crate::checkpoint;
use crate::config::ModelConfig;
use crate::error::{Error, Result};
use crate::inference::ddim_sample;
use crate::model::{Crop, ScaleDp};
use crate::scheduler::NoiseScheduler;
use crate::trainer::optim::{ema_update, AdamW};
use crate::trainer::{
    candle_loss_and_grads, loss_and_grads, LossSpec, Phases, TrainOptions, Trainer,
};

/// Training throughput of one configuration.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TrainThroughput {
    /// Samples per step.
    pub batch_size: usize,
    /// Steps timed (after the warm-up ones).
    pub steps: usize,
    /// Mean wall time of a step (s).
    pub step_s: f64,
    /// Samples per second.
    pub samples_per_s: f64,
    /// Share of step time spent waiting for the loader.
    pub data_wait_share: f64,
    /// Parameters: encoders, denoiser.
    pub params: (usize, usize),
    /// Mean time per step of the encoders, the denoiser and loss, the backward pass (s).
    pub phases: Phases,
    /// Mean time per step of AdamW and the EMA (s).
    pub optimizer_s: f64,
    /// CPU time of the process per step (s; all threads), where readable.
    pub cpu_s: Option<f64>,
}

/// Trains `steps` steps (after `warmup` untimed ones) on `dataset` with `opts` into a scratch
/// directory and reports the throughput. The run's initial weights are those of
/// `opts`' seed, so [`write_torch_case`] can hand PyTorch the same ones.
pub fn train_throughput(
    dataset: &str,
    opts: TrainOptions,
    warmup: usize,
    steps: usize,
    device: &Device,
) -> Result<TrainThroughput> {
    let dir = std::env::temp_dir().join(format!("scaledp-bench-train-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let opts = opts
        .steps((warmup + steps) as u64 + 1)
        .val_every(0)
        .checkpoint_every(0);
    let mut t = Trainer::new(dataset, &dir, opts, device)?;
    for _ in 0..warmup {
        t.step()?;
    }
    let (mut busy, mut wait, mut samples) = (0f64, 0f64, 0usize);
    let (mut phases, mut optimizer_s) = (Phases::default(), 0f64);
    let cpu0 = process_cpu_s();
    for _ in 0..steps {
        let r = t.step()?;
        busy += r.step_s;
        wait += r.data_wait_s;
        samples += r.samples;
        phases.encode_s += r.phases.encode_s;
        phases.denoise_s += r.phases.denoise_s;
        phases.backward_s += r.phases.backward_s;
        optimizer_s += r.optimizer_s;
    }
    let cpu = cpu0
        .zip(process_cpu_s())
        .map(|(a, b)| (b - a) / steps.max(1) as f64);
    let counts = ScaleDp::count(&t.config().model)?;
    let _ = std::fs::remove_dir_all(&dir);
    let n = steps.max(1) as f64;
    Ok(TrainThroughput {
        batch_size: t.options().get_batch_size(),
        steps,
        step_s: busy / n,
        samples_per_s: samples as f64 / busy.max(1e-9),
        data_wait_share: wait / busy.max(1e-9),
        params: (counts.encoders, counts.denoiser),
        phases: Phases {
            encode_s: phases.encode_s / n,
            denoise_s: phases.denoise_s / n,
            backward_s: phases.backward_s / n,
        },
        optimizer_s: optimizer_s / n,
        cpu_s: cpu,
    })
}

/// Writes `config.json` (checkpoint style) and `model.safetensors` with the initial weights a
/// run of `cfg` seeded by `seed` starts from, for `tests/py/bench_train_torch.py`.
pub fn write_torch_case(dir: &Path, cfg: &ModelConfig, seed: u64) -> Result<(PathBuf, PathBuf)> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let model = ScaleDp::new(cfg, seed, &Device::Cpu)?;
    let weights = dir.join(checkpoint::MODEL_FILE);
    model.save(&weights)?;
    let config = dir.join(checkpoint::CONFIG_FILE);
    let v = serde_json::json!({"model": cfg});
    std::fs::write(&config, v.to_string()).map_err(|e| Error::io(&config, e))?;
    Ok((config, weights))
}

/// DDIM latency of one action chunk (batch 1: encoders once, the denoiser once per step).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Latency {
    /// Chunks timed.
    pub runs: usize,
    /// Median (ms).
    pub p50_ms: f64,
    /// 99th percentile (ms).
    pub p99_ms: f64,
    /// Median time of the encoders alone (ms; the rest is the denoiser's passes).
    pub encode_p50_ms: f64,
}

/// Times `runs` DDIM samples (after 2 untimed) of a model of `cfg` with random weights.
pub fn ddim_latency(
    cfg: &ModelConfig,
    steps: usize,
    runs: usize,
    device: &Device,
) -> Result<Latency> {
    let model = ScaleDp::random(cfg, 0, 0.02, device)?;
    let mut sched = NoiseScheduler::new(100)?;
    sched.set_timesteps(steps)?;
    let n_img =
        cfg.obs_horizon * cfg.cameras.len() * 3 * (cfg.image_width * cfg.image_height) as usize;
    let images: Vec<u8> = (0..n_img).map(|i| (i % 251) as u8).collect();
    let state = vec![0.1f32; cfg.obs_horizon * cfg.state_dim];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let mut times = Vec::with_capacity(runs);
    let mut encode = Vec::with_capacity(runs);
    let mut engine = crate::engine::Engine::default();
    for i in 0..runs + 2 {
        let t0 = Instant::now();
        if device.is_cpu() {
            engine.sample(&model, &sched, &images, &state, 1, &mut rng)?;
            if i >= 2 {
                encode.push(engine.last_encode_s() * 1e3);
            }
        } else {
            let t = Instant::now();
            let cond = model.encode(&images, &state, 1, Crop::Center, &mut rng)?;
            if i >= 2 {
                encode.push(t.elapsed().as_secs_f64() * 1e3);
            }
            let x = ddim_sample(&model, &sched, &cond, &mut rng)?;
            x.flatten_all()?.to_vec1::<f32>()?;
        }
        if i >= 2 {
            times.push(t0.elapsed().as_secs_f64() * 1e3);
        }
    }
    let at = |v: &mut Vec<f64>, q: f64| {
        v.sort_by(f64::total_cmp);
        v[((v.len() - 1) as f64 * q).round() as usize]
    };
    Ok(Latency {
        runs,
        p50_ms: at(&mut times, 0.5),
        p99_ms: at(&mut times, 0.99),
        encode_p50_ms: at(&mut encode, 0.5),
    })
}

/// CPU time (user + system) this process has used so far (s), from `/proc/self/stat`; `None`
/// where that is not readable.
pub fn process_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may hold spaces) in parentheses.
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let (utime, stime): (f64, f64) = (f.get(11)?.parse().ok()?, f.get(12)?.parse().ok()?);
    // USER_HZ is 100 on every Linux configuration that matters here.
    Some((utime + stime) / 100.0)
}

/// Where the time of training steps on a synthetic batch went (means per step).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StepProfile {
    /// Samples per step.
    pub batch_size: usize,
    /// Steps timed.
    pub steps: usize,
    /// Wall time of a step (s).
    pub step_s: f64,
    /// CPU time of the process per step (s; user + system, all threads).
    pub cpu_s: Option<f64>,
    /// Forward passes and backward.
    pub phases: Phases,
    /// AdamW and the EMA (s).
    pub optimizer_s: f64,
}

/// Trains a fresh model of `cfg` (seed `seed`) on one synthetic batch of `batch_size` samples
/// (random images, state and actions, no padding) for `warmup` + `steps` steps, with the
/// trainer's loss (`spec`), backward pass, AdamW and EMA, and reports where the timed steps'
/// time went. No loader: this isolates the model's cost from data loading. `autograd` takes
/// candle's autograd on the candle modules instead of the CPU engine (for comparison).
#[allow(clippy::too_many_arguments)]
pub fn synthetic_step_profile(
    cfg: &ModelConfig,
    batch_size: usize,
    micro_batch: Option<usize>,
    spec: LossSpec,
    warmup: usize,
    steps: usize,
    seed: u64,
    autograd: bool,
) -> Result<StepProfile> {
    let dev = Device::Cpu;
    let (model, params) = ScaleDp::fresh(cfg, seed, &dev)?;
    let ema = crate::trainer::checkpointing::copy_model(cfg, &params, &dev)?.1;
    let mut optim = AdamW::new(params, crate::trainer::AdamWConfig::default())?;
    let sched = NoiseScheduler::new(100)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let batch = synthetic_batch(cfg, batch_size, &mut rng);
    let mut engine = crate::engine::Engine::default();
    let (mut phases, mut opt_s, mut wall) = (Phases::default(), 0f64, 0f64);
    let mut cpu0 = None;
    for i in 0..warmup + steps {
        if i == warmup {
            cpu0 = process_cpu_s();
        }
        let t0 = Instant::now();
        let mut p = Phases::default();
        let (_, grads) = if autograd {
            candle_loss_and_grads(
                &model,
                &sched,
                optim.params(),
                &batch,
                spec,
                micro_batch,
                &mut rng,
                &mut p,
            )?
        } else {
            loss_and_grads(
                &model,
                &mut engine,
                &sched,
                optim.params(),
                &batch,
                spec,
                micro_batch,
                &mut rng,
                &mut p,
            )?
        };
        let t1 = Instant::now();
        optim.step(&grads, 1e-4, 1.0)?;
        ema_update(&ema, optim.params(), 0.9)?;
        if i >= warmup {
            opt_s += t1.elapsed().as_secs_f64();
            wall += t0.elapsed().as_secs_f64();
            phases.encode_s += p.encode_s;
            phases.denoise_s += p.denoise_s;
            phases.backward_s += p.backward_s;
        }
    }
    let cpu = match (cpu0, process_cpu_s()) {
        (Some(a), Some(b)) => Some(b - a),
        _ => None,
    };
    let n = steps.max(1) as f64;
    Ok(StepProfile {
        batch_size,
        steps,
        step_s: wall / n,
        cpu_s: cpu.map(|c| c / n),
        phases: Phases {
            encode_s: phases.encode_s / n,
            denoise_s: phases.denoise_s / n,
            backward_s: phases.backward_s / n,
        },
        optimizer_s: opt_s / n,
    })
}

/// A batch of `b` samples for `cfg` with random images (uint8), state and actions.
pub fn synthetic_batch(
    cfg: &ModelConfig,
    b: usize,
    rng: &mut rand_chacha::ChaCha8Rng,
) -> scaledp_datasets::Batch {
    use rand::Rng;
    let (to, ch, cams) = (cfg.obs_horizon, cfg.action_chunk, cfg.cameras.len());
    let (w, h) = (cfg.image_width, cfg.image_height);
    let n_img = b * to * cams * 3 * (w * h) as usize;
    scaledp_datasets::Batch {
        len: b,
        obs_horizon: to,
        action_chunk: ch,
        cameras: cfg.cameras.clone(),
        height: h,
        width: w,
        state_dim: cfg.state_dim,
        action_dim: cfg.action_dim,
        images: (0..n_img).map(|_| rng.random::<u8>()).collect(),
        state: (0..b * to * cfg.state_dim)
            .map(|_| rng.random_range(-1f32..1.0))
            .collect(),
        action: (0..b * ch * cfg.action_dim)
            .map(|_| rng.random_range(-1f32..1.0))
            .collect(),
        obs_is_pad: vec![false; b * to],
        action_is_pad: vec![false; b * ch],
        episode_index: vec![0; b],
        frame_index: (0..b as i64).collect(),
    }
}

/// Median milliseconds of one convolution's three products on the CPU engine's kernels, for
/// comparing layer by layer with another framework: `[forward, input gradient, weight
/// gradient]` of a `c_in → c_out`, `k×k`, stride `stride`, padding `k/2` convolution over
/// `batch` channels-last `hw×hw` inputs, each timed `reps` times after one untimed call.
pub fn conv_op_ms(
    batch: usize,
    (c_in, c_out): (usize, usize),
    hw: usize,
    k: usize,
    stride: usize,
    reps: usize,
) -> Result<[f64; 3]> {
    use crate::model::conv::{self, Geom};
    let g = Geom::new(&[batch, hw, hw, c_in], &[c_out, c_in, k, k], stride, k / 2)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let x = crate::model::params::randn(&mut rng, batch * g.per_in());
    let w = crate::model::params::randn(&mut rng, c_out * g.k());
    let dy = crate::model::params::randn(&mut rng, batch * g.pixels() * c_out);
    let (mut y, mut dx, mut dw) = (
        vec![0f32; dy.len()],
        vec![0f32; x.len()],
        vec![0f32; w.len()],
    );
    let median = |f: &mut dyn FnMut()| {
        f();
        let mut t: Vec<f64> = (0..reps.max(1))
            .map(|_| {
                let t0 = Instant::now();
                f();
                t0.elapsed().as_secs_f64() * 1e3
            })
            .collect();
        t.sort_by(f64::total_cmp);
        t[t.len() / 2]
    };
    Ok(crate::model::cpu::on_pool(|| {
        [
            median(&mut || conv::forward(&g, &x, &w, false, &mut y)),
            median(&mut || conv::grad_input(&g, &dy, &w, &mut dx, false)),
            median(&mut || conv::grad_weight(&g, &x, &dy, &mut dw)),
        ]
    }))
}
