//! `scaledp bench train`: ScaleDP-Ti's and DP-T's training throughput on this machine's cores —
//! on a dataset converted from simulated recordings (2 cameras, images as the converter writes
//! them unless `--image-size`, cropped to 0.9), To 2, C 16, batch 64 — with the share of step
//! time spent waiting for the loader; the same step on a synthetic batch (compute only), and the
//! same model in PyTorch (the wheel's `scaledp_data.policy`) on a synthetic batch from the same
//! initial weights on the same threads (when the benchmark venv has torch); each step's FLOPs
//! (counted from the layer shapes) over its time beside this machine's FP32 matrix-multiply
//! peak; and DDIM-10 latency per action chunk for Ti, S and DP-T.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{bail, Context, Result};
use candle_core::Device;
use scaledp_converter::{ConvertOptions, InputResult, JobOptions, Unlabeled};
use scaledp_policy::bench::{
    ddim_latency, synthetic_step_profile, train_throughput, write_torch_case,
};
use scaledp_policy::flops::{matmul_peak_gflops, step_flops};
use scaledp_policy::{Architecture, ModelConfig, ModelSize, Phases, TrainOptions, Trainer};
use scaledp_schema::Rig;
use scaledp_testkit::BENCH_VENV;

use crate::args::BenchTrainArgs;
use crate::python::{NotRun, Python, Script};
use crate::synth::synthesize;
use crate::Outcome;

/// The PyTorch side: times the wheel's module's training step.
const TORCH_TRAIN: Script = Script {
    name: "bench_train_torch.py",
    text: include_str!("../../tests/py/bench_train_torch.py"),
};

/// Runs `scaledp bench train`.
pub fn run(args: BenchTrainArgs) -> Result<Outcome> {
    if args.steps == 0 || args.latency_runs == 0 || args.rounds == 0 {
        bail!("--steps, --latency-runs and --rounds must be at least 1");
    }
    let archs = args
        .models
        .iter()
        .map(|m| match m.as_str() {
            "ti" => Ok(Architecture::ScaleDp),
            "dp-t" | "dpt" => Ok(Architecture::DpT),
            other => bail!("--models {other}: ti or dp-t"),
        })
        .collect::<Result<Vec<_>>>()?;
    let mut base = match &args.preset {
        Some(p) => TrainOptions::preset(p).with_context(|| {
            format!(
                "--preset {p}: one of {}",
                scaledp_policy::PRESETS.join(", ")
            )
        })?,
        None => TrainOptions::default(),
    };
    // ScaleDP's attention; `model_round`'s switch to DP-T resets it to DP-T's own masks.
    if let Some(at) = &args.attention {
        base = base.attention(at.parse().context("--attention")?);
    }
    let size = args.image_size.as_deref().map(parse_size).transpose()?;
    let tmp = tempfile::tempdir().context("creating a temporary directory")?;
    let work = args.out.clone().unwrap_or_else(|| tmp.path().to_path_buf());
    let dataset = make_dataset(&work, &args, size)?;
    let ds = dataset.to_string_lossy().to_string();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let peak = matmul_peak_gflops(1024, 5);
    println!(
        "this machine's FP32 matrix-multiply peak: {peak:.1} GFLOP/s on {threads} threads (the best of 6 products of two 1024×1024 matrices by the engine's GEMM)"
    );
    let mut cfg = None;
    for arch in archs {
        cfg = Some(model_round(
            &args,
            &ds,
            &work,
            base.clone(),
            arch,
            size,
            threads,
            peak,
        )?);
    }
    let Some(cfg) = cfg else {
        bail!("--models: name at least one of ti, dp-t");
    };
    let inputs = (
        cfg.cameras.clone(),
        (cfg.image_width, cfg.image_height),
        cfg.state_dim,
        cfg.action_dim,
    );
    // ScaleDP's latency rows use the attention its training rows use (the preset's, or
    // `--attention`), even when `--models` leaves ScaleDP out; DP-T keeps its own masks.
    let scaledp_attention = Trainer::plan(&ds, &base.arch(Architecture::ScaleDp))?
        .model
        .attention;
    let mut models = vec![
        ModelConfig::new(
            ModelSize::Ti,
            inputs.0.clone(),
            inputs.1,
            inputs.2,
            inputs.3,
        ),
        ModelConfig::new(ModelSize::S, inputs.0.clone(), inputs.1, inputs.2, inputs.3),
        ModelConfig::dp_t(inputs.0, inputs.1, inputs.2, inputs.3),
    ];
    println!();
    for c in &mut models {
        c.obs_horizon = cfg.obs_horizon;
        c.action_chunk = cfg.action_chunk;
        if c.arch == Architecture::ScaleDp {
            c.attention = scaledp_attention;
        }
        let l = ddim_latency(c, 10, args.latency_runs, &Device::Cpu)?;
        println!(
            "DDIM-10 {:<10} {} attention, per action chunk (batch 1, {} runs): p50 {:.1} ms (encoders {:.1} ms), p99 {:.1} ms (goal < 100 ms)",
            c.denoiser_name(), c.attention, l.runs, l.p50_ms, l.encode_p50_ms, l.p99_ms
        );
    }
    Ok(Outcome::Completed)
}

/// One model's figures: the training throughput with the loader, then the synthetic step
/// against PyTorch's for `--rounds` alternating rounds, each step's FLOPs over its time beside
/// the machine's matrix-multiply peak. Returns the model's configuration.
#[allow(clippy::too_many_arguments)]
fn model_round(
    args: &BenchTrainArgs,
    ds: &str,
    work: &Path,
    base: TrainOptions,
    arch: Architecture,
    size: Option<(u32, u32)>,
    threads: usize,
    peak: f64,
) -> Result<ModelConfig> {
    let batch = args.batch_size.unwrap_or(base.get_batch_size());
    let mut opts = base
        .arch(arch)
        .batch_size(batch)
        .val_ratio(0.0)
        .val_every(0)
        .seed(0);
    if arch == Architecture::ScaleDp {
        opts = opts.model(ModelSize::Ti);
    }
    let k = opts.get_loss().noise_samples;
    if let Some((w, h)) = size {
        opts = opts.image_size(w, h);
    }
    if let Some(m) = args.micro_batch {
        opts = opts.micro_batch(m);
    }
    let cfg = Trainer::plan(ds, &opts)?.model;
    let (cw, ch) = cfg.crop_size();
    let flops = step_flops(&cfg, batch, k);
    println!(
        "\n{}, {} attention, {} cameras {}x{} cropped to {cw}x{ch}, ResNet width {}, state {}, action {}, To {}, C {}, batch {batch}, {k} noise draw(s) per observation, {threads} threads; a step is {:.1} GFLOP ({:.1} encoders, {:.1} denoiser; counted from the layer shapes)",
        cfg.denoiser_name(), cfg.attention, cfg.cameras.len(), cfg.image_width, cfg.image_height, cfg.resnet_width, cfg.state_dim, cfg.action_dim,
        cfg.obs_horizon, cfg.action_chunk, flops.total() / 1e9, flops.encoders / 1e9, flops.denoiser / 1e9
    );
    let share = |step_s: f64| flops.total() / step_s.max(1e-9) / 1e9 / peak.max(1e-9);
    eprintln!(
        "training {} + {} warm-up steps in Rust (CPU engine)…",
        args.steps, args.warmup
    );
    let spec = opts.get_loss();
    let t = train_throughput(ds, opts, args.warmup, args.steps, &Device::Cpu)?;
    println!(
        "rust (CPU engine) {:>7.2} s/step  {:>7.2} samples/s  data wait {:.1} % of step time (goal < 5 %); {:.2} of the matmul peak",
        t.step_s,
        t.samples_per_s,
        100.0 * t.data_wait_share,
        share(t.step_s)
    );
    print_phases(
        &t.phases,
        t.step_s,
        t.optimizer_s,
        t.cpu_s,
        "data and the rest",
    );
    // The PyTorch route times a step on a synthetic batch, with no loader beside it: so does
    // this one, for a like-for-like ratio (the loader's decoding shares the same two cores).
    // This machine's speed drifts by 10-20 % within minutes, so the two sides alternate for
    // `--rounds` rounds and the figure is the median of the rounds' ratios.
    let mut ratios = Vec::new();
    let mut shares = Vec::new();
    for round in 1..=args.rounds {
        let s = synthetic_step_profile(
            &cfg,
            batch,
            args.micro_batch,
            spec,
            args.warmup,
            args.steps,
            0,
            false,
        )?;
        shares.push(share(s.step_s));
        println!(
            "round {round}: rust, synthetic batch {:>7.2} s/step  {:>7.2} samples/s  (compute only, as PyTorch's); {:.1} GFLOP/s = {:.2} of the matmul peak",
            s.step_s,
            batch as f64 / s.step_s.max(1e-9),
            flops.total() / s.step_s.max(1e-9) / 1e9,
            share(s.step_s)
        );
        print_phases(&s.phases, s.step_s, s.optimizer_s, s.cpu_s, "the rest");
        match torch_route(args, &cfg, work, threads, batch, k) {
            Ok(v) => {
                let torch_s = v["mean_step_s"].as_f64().unwrap_or(f64::NAN);
                println!(
                    "round {round}: pytorch {}    {torch_s:>7.2} s/step  {:>7.2} samples/s  (same weights, synthetic batch, {threads} threads, after {} warm-up steps); {:.2} of the matmul peak; ratio {:.2}×",
                    v["torch"].as_str().unwrap_or("?"),
                    v["samples_per_s"].as_f64().unwrap_or(f64::NAN),
                    args.warmup,
                    share(torch_s),
                    torch_s / s.step_s,
                );
                ratios.push((torch_s / s.step_s, torch_s));
            }
            Err(why) => {
                println!("pytorch         not measured: {why}");
                break;
            }
        }
    }
    shares.sort_by(f64::total_cmp);
    if let Some(m) = shares.get(shares.len() / 2) {
        println!(
            "{}: the training step runs at {m:.2} of this machine's FP32 matmul peak (median of the rounds; goal ≥ 0.6)",
            cfg.denoiser_name()
        );
    }
    if !ratios.is_empty() {
        ratios.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (median, torch_s) = ratios[ratios.len() / 2];
        let range = (ratios[0].0, ratios[ratios.len() - 1].0);
        println!(
            "{}: rust ÷ pytorch speed, both on a synthetic batch: {median:.2}× (median of {} alternating rounds, {:.2}–{:.2}; PyTorch's s/step over ours; goal ≥ 1.0)",
            cfg.denoiser_name(),
            ratios.len(),
            range.0,
            range.1
        );
        println!(
            "  with the loader feeding ours: {:.2}× (against the median round's PyTorch step)",
            torch_s / t.step_s
        );
    }
    Ok(cfg)
}

/// One line of where a step's time goes; `rest` names what the phases leave out.
fn print_phases(p: &Phases, step_s: f64, optimizer_s: f64, cpu_s: Option<f64>, rest: &str) {
    let other = (step_s - p.encode_s - p.denoise_s - p.backward_s - optimizer_s).max(0.0);
    println!(
        "  where a step goes: encoders {:.3} s, denoiser + loss {:.3} s, backward {:.3} s, AdamW + EMA {optimizer_s:.3} s, {rest} {other:.3} s; {} cores busy",
        p.encode_s,
        p.denoise_s,
        p.backward_s,
        cpu_s.map_or("?".into(), |c| format!("{:.2}", c / step_s.max(1e-9)))
    );
}

/// Simulated recordings of the franka rig, converted into a dataset under `work` (at `size`
/// when given).
fn make_dataset(work: &Path, args: &BenchTrainArgs, size: Option<(u32, u32)>) -> Result<PathBuf> {
    let rig =
        Rig::load_or_builtin(&args.rig).with_context(|| format!("loading rig {}", args.rig))?;
    let recordings = work.join("recordings");
    std::fs::create_dir_all(&recordings)
        .with_context(|| format!("creating {}", recordings.display()))?;
    let jobs = std::thread::available_parallelism().map_or(1, |n| n.get());
    let ids: Vec<usize> = (0..args.episodes).collect();
    eprintln!(
        "simulating {} episodes of {} s ({})…",
        args.episodes, args.seconds, rig.name
    );
    let paths = synthesize(
        &recordings,
        &rig,
        &ids,
        args.seconds,
        "put the red cube on the green square",
        jobs,
    )?;
    let dataset = work.join("dataset");
    eprintln!("converting…");
    let results = scaledp_converter::run(
        &paths,
        &dataset,
        &JobOptions::default()
            // The simulator's recordings hold the training streams only (no depth).
            .convert(
                size.map_or(ConvertOptions::default(), |(w, h)| {
                    ConvertOptions::default().size(w, h)
                })
                .depth(false),
            )
            .overwrite(true)
            .unlabeled(Unlabeled::Keep),
        &|_| {},
    )?;
    for (path, r) in &results {
        if let InputResult::Failed(e) = r {
            bail!("converting {}: {}", path.display(), e.one_line());
        }
    }
    Ok(dataset)
}

/// The PyTorch route's JSON report, or why there is none.
fn torch_route(
    args: &BenchTrainArgs,
    cfg: &ModelConfig,
    work: &Path,
    threads: usize,
    batch: usize,
    noise_samples: usize,
) -> Result<serde_json::Value, NotRun> {
    if args.no_python {
        return Err(NotRun::Skipped);
    }
    let py = Python::locate(&BENCH_VENV, args.python.as_deref())?;
    let (config, weights) = write_torch_case(&work.join("torch-case"), cfg, 0)
        .map_err(|e| NotRun::Failed(e.to_string()))?;
    // The PyTorch module is the wheel's (scripts/build-python.sh), unpacked onto PYTHONPATH.
    let site = work.join("py-site");
    py.unpack_wheel(&site)?;
    let mut cmd = py.command(&TORCH_TRAIN)?;
    cmd.env("PYTHONPATH", &site)
        .arg(config)
        .arg(weights)
        .args(["--batch", &batch.to_string()])
        .args(["--noise-samples", &noise_samples.to_string()])
        .args(["--steps", &args.steps.to_string()])
        .args(["--warmup", &args.warmup.to_string()])
        .args(["--threads", &threads.to_string()]);
    eprintln!("training the same model in PyTorch…");
    let (v, _) = py.run_json(cmd, Duration::from_secs(1800))?;
    if let Some(e) = v["error"].as_str() {
        return Err(NotRun::NotSetUp(format!(
            "{e} in the benchmark venv (bash scripts/setup-bench-python.sh)"
        )));
    }
    Ok(v)
}

fn parse_size(s: &str) -> Result<(u32, u32)> {
    let (w, h) = s
        .split_once('x')
        .with_context(|| format!("--image-size {s}: WxH, e.g. 84x84"))?;
    Ok((
        w.parse().with_context(|| format!("--image-size {s}"))?,
        h.parse().with_context(|| format!("--image-size {s}"))?,
    ))
}
