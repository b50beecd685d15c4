//! `scaledp demo`: the whole path in one process — the simulated rig and the recorder over
//! loopback, then the converter into a LeRobot dataset beside the recordings, then one epoch
//! through the training-data loader, a short ScaleDP-Ti training run and one `predict`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use anyhow::{Context, Result};
use candle_core::Device;
use indicatif::{ProgressBar, ProgressStyle};
use scaledp_converter::{InputResult, JobOptions, Progress};
use scaledp_datasets::LoaderOptions;
use scaledp_policy::{predict_episode, Event, ModelSize, Policy, TrainOptions, Trainer};
use scaledp_recorder::{net, Label, RecorderOptions};
use scaledp_schema::Rig;

use crate::cli::{DemoArgs, ExitStatus};
use crate::shared::{self, timed_episodes, wait_for_topics};
use crate::ui::topic_labels;
use scaledp_sim::SimOptions;

pub fn run(args: DemoArgs) -> Result<ExitStatus> {
    let rig = Rig::load_or_builtin(&args.rig)?;
    let endpoint = format!("tcp/127.0.0.1:{}", shared::free_port()?);
    eprintln!(
        "simulating rig '{}' on {endpoint}; recording {} episodes of {} s",
        rig.name, args.episodes, args.duration
    );
    let sim_session = net::open(net::zenoh_config(
        None,
        &[],
        std::slice::from_ref(&endpoint),
    )?)?;
    // The scripted teleoperator demonstrates the cube task, episode after episode.
    let sim = SimOptions::new(rig.clone())
        .seed(args.seed)
        .scripted_operator(true)
        .autoplay(true)
        .spawn(&sim_session)?;
    let out = args.out.join("recordings");
    let recorder = RecorderOptions::new(rig.clone(), &out)
        .task("put the red cube on the green square")
        .operator("scaledp demo")
        .start(net::zenoh_config(None, &[endpoint], &[])?)?;
    let stop = shared::interrupt_flag();
    wait_for_topics(&recorder, 15.0, &stop);
    let tally = timed_episodes(
        &recorder,
        Some(args.episodes),
        args.duration,
        Label::Success,
        &stop,
        topic_labels(&rig),
        args.retries,
    );
    recorder.finish()?;
    sim.stop();
    let _ = zenoh::Wait::wait(sim_session.close());

    let mut per_topic: BTreeMap<&str, (u64, u64, u64)> = BTreeMap::new();
    let kept: Vec<_> = tally.kept_episodes().collect();
    let seconds: f64 = kept.iter().map(|r| r.duration_s).sum();
    for r in &kept {
        for (topic, n) in &r.summary.messages {
            let e = per_topic.entry(topic).or_default();
            e.0 += n;
            e.1 += r.summary.bytes[topic];
            e.2 += r.dropped[topic] + r.upstream_gaps[topic];
        }
    }
    let again = match tally.rerecorded {
        0 => String::new(),
        n => format!(" ({n} recorded again: convert would have rejected them; in discarded/)"),
    };
    println!(
        "\n{} episodes, {seconds:.1} s in all, in {}{again}",
        kept.len(),
        out.display()
    );
    println!(
        "{:<48} {:>9} {:>8} {:>9} {:>6}",
        "topic", "messages", "rate Hz", "MB", "lost"
    );
    for (topic, (n, bytes, lost)) in &per_topic {
        let rate = if seconds > 0.0 {
            *n as f64 / seconds
        } else {
            0.0
        };
        println!(
            "{topic:<48} {n:>9} {rate:>8.1} {:>9.1} {lost:>6}",
            *bytes as f64 / 1e6
        );
    }
    println!("\nopen them in Foxglove or rerun, or: python -c \"from rosbags.highlevel import AnyReader\"");

    let recordings: Vec<PathBuf> = kept.iter().map(|r| r.summary.path.clone()).collect();
    if recordings.is_empty() {
        anyhow::bail!("no episode was recorded");
    }
    let dataset = args.out.join("dataset");
    let converted = convert(&recordings, &dataset)?;
    load_one_epoch(&dataset, args.batch_size as usize)?;
    if args.train_steps > 0 {
        train_and_predict(&dataset, &args.out.join("run"), args.train_steps, args.seed)?;
    }
    Ok(
        if tally.lost() > 0 || tally.failed > 0 || converted < recordings.len() {
            ExitStatus::DataLost
        } else {
            ExitStatus::Success
        },
    )
}

/// Converts this run's recordings into a fresh dataset at `dataset`; returns how many made it.
fn convert(recordings: &[PathBuf], dataset: &Path) -> Result<usize> {
    let bar = ProgressBar::new(recordings.len() as u64).with_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} episodes converted {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let frames = AtomicU64::new(0);
    let start = Instant::now();
    let opts = JobOptions::default().overwrite(true);
    let results = scaledp_converter::run(recordings, dataset, &opts, &|p| {
        if let Progress::Done {
            result, frames: f, ..
        } = p
        {
            if let InputResult::Failed(e) = result {
                bar.suspend(|| eprintln!("error: {}", e.one_line()));
            }
            let total = frames.fetch_add(f as u64, Ordering::Relaxed) + f as u64;
            bar.set_message(format!("{total} frames"));
            bar.inc(1);
        }
    })
    .with_context(|| format!("converting into {}", dataset.display()))?;
    bar.finish_and_clear();
    let converted = results
        .iter()
        .filter(|(_, o)| matches!(o, InputResult::Converted(_)))
        .count();
    for (path, o) in &results {
        match o {
            InputResult::Skipped(why) => eprintln!("skipped {}: {why}", path.display()),
            InputResult::Failed(e) => eprintln!("failed: {}", e.one_line()),
            InputResult::Converted(_) => {}
        }
    }
    println!(
        "\nconverted {converted} of {} episodes ({} frames) in {:.1} s → {} (LeRobot v3.0, 320×240 JPEG)",
        recordings.len(),
        frames.load(Ordering::Relaxed),
        start.elapsed().as_secs_f64(),
        dataset.display()
    );
    if converted == 0 {
        anyhow::bail!("no episode could be converted");
    }
    Ok(converted)
}

/// One shuffled epoch through the loader (To 2, C 16), with a summary of what came out.
fn load_one_epoch(dataset: &Path, batch_size: usize) -> Result<()> {
    let start = Instant::now();
    let mut loader = LoaderOptions::default()
        .batch_size(batch_size)
        .open(&dataset.to_string_lossy())
        .with_context(|| format!("opening {}", dataset.display()))?;
    let info = loader.info().clone();
    let (mut samples, mut batches, mut shapes) = (0usize, 0usize, String::new());
    let epoch = Instant::now();
    while let Some(batch) = loader.next_batch() {
        let b = batch?;
        if shapes.is_empty() {
            shapes = format!(
                "images [{}, {}, {}, 3, {}, {}] u8, state [{}, {}, {}] f32, action [{}, {}, {}] f32 in [-1, 1]",
                b.len, b.obs_horizon, b.cameras.len(), b.height, b.width,
                b.len, b.obs_horizon, b.state_dim,
                b.len, b.action_chunk, b.action_dim
            );
        }
        samples += b.len;
        batches += 1;
        loader.recycle(b);
    }
    let epoch_s = epoch.elapsed().as_secs_f64();
    println!(
        "loader: {} episodes, {} frames, {samples} samples in {batches} batches of ≤ {batch_size}; first batch {shapes}",
        info.episodes.len(),
        info.frames,
    );
    println!(
        "one epoch in {epoch_s:.2} s ({:.0} samples/s; opened in {:.2} s), cameras {}",
        samples as f64 / epoch_s.max(1e-9),
        (start.elapsed().as_secs_f64() - epoch_s).max(0.0),
        info.cameras.join(", ")
    );
    Ok(())
}

/// A short ScaleDP-Ti run on the demo dataset (84×84 images, batch 8) and one `predict` over
/// its first episode, so the whole path sim → recorder → converter → loader → ScaleDP runs from
/// one command. A few dozen steps train nothing useful; they show the loss falling, a
/// checkpoint written and read back, and DDIM samples coming out in metres and radians.
fn train_and_predict(dataset: &Path, run: &Path, steps: u64, seed: u64) -> Result<()> {
    let ds = dataset.to_string_lossy();
    let opts = TrainOptions::default()
        .model(ModelSize::Ti)
        .steps(steps)
        .batch_size(8)
        .warmup_steps(steps.div_ceil(5))
        .lr(3e-4)
        .image_size(84, 84)
        .seed(seed)
        .checkpoint_every(steps)
        .val_ratio(0.0)
        .val_every(0);
    if run.exists() {
        std::fs::remove_dir_all(run).with_context(|| format!("removing {}", run.display()))?;
    }
    let start = Instant::now();
    let mut trainer = Trainer::new(&ds, run, opts, &Device::Cpu)?;
    let bar = ProgressBar::new(steps);
    bar.set_style(ProgressStyle::with_template(
        "training ScaleDP-Ti {bar:30} {pos}/{len} steps  {msg}  [{elapsed_precise}]",
    )?);
    let (mut first, mut last) = (None, None);
    let summary = trainer.run(|e| {
        if let Event::Step(r) = e {
            first.get_or_insert(r.loss);
            last = Some(r.loss);
            bar.set_position(r.step);
            bar.set_message(format!("loss {:.4}", r.loss));
        }
    })?;
    bar.finish_and_clear();
    let checkpoint = summary
        .checkpoint
        .context("the training run wrote no checkpoint")?;
    println!(
        "trained ScaleDP-Ti for {} steps in {:.1} s: loss {} → {}; checkpoint {}",
        summary.steps,
        start.elapsed().as_secs_f64(),
        first.map_or("-".into(), |l| format!("{l:.4}")),
        last.map_or("-".into(), |l| format!("{l:.4}")),
        checkpoint.display()
    );
    let start = Instant::now();
    let policy = Policy::load(&checkpoint, &Device::Cpu)?;
    let p = predict_episode(&policy, &ds, 0, 16, seed)?;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    println!(
        "predict: episode {}, {} chunks of {} in {:.1} s; mean absolute error per action dimension {:.4} \
         (untrained: `scaledp train` for real steps, `scaledp predict` for the per-dimension table)",
        p.episode,
        p.frames.len(),
        p.action_chunk,
        start.elapsed().as_secs_f64(),
        mean(&p.mae),
    );
    Ok(())
}
