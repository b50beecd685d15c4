//! `scaledp convert` and `scaledp dataset merge`, local or on object storage.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use anyhow::Result;
use indicatif::{ProgressBar, ProgressStyle};
use scaledp_converter::{
    ConvertOptions, InputResult, JobOptions, Location, MergeOptions, Progress, Unlabeled,
    VideoCodec,
};
use scaledp_schema::Rig;

use crate::cli::{ConvertArgs, ExitStatus, MergeArgs, UnlabeledArg, VideoArg};
use crate::shared::location;

pub fn run(args: ConvertArgs) -> Result<ExitStatus> {
    let rig = args.rig.as_deref().map(Rig::load_or_builtin).transpose()?;
    let locations = args
        .inputs
        .iter()
        .map(|p| location(p))
        .collect::<Result<Vec<_>>>()?;
    let out = location(&args.out)?;
    let inputs = scaledp_converter::collect(&locations)?;
    if inputs.is_empty() {
        anyhow::bail!(
            "no .mcap, .bag, .db3 or rosbag2 directory found in {:?}",
            args.inputs
        );
    }
    let mut convert = ConvertOptions::default()
        .size(args.size.0, args.size.1)
        .jpeg_quality(args.jpeg_quality)
        .stale_periods(args.stale_periods)
        .max_invalid_fraction(args.max_invalid)
        .use_log_time(args.log_time)
        .reorder_window(args.reorder_window)
        .action_space(args.action_space)
        .depth(!args.no_depth)
        .video(args.video.map(|v| match v {
            VideoArg::Av1 => VideoCodec::Av1,
            VideoArg::H264 => VideoCodec::H264,
        }));
    if let Some(rig) = rig {
        convert = convert.rig(rig);
    }
    if let Some(fps) = args.fps {
        convert = convert.fps(fps);
    }
    if let Some(task) = args.task {
        convert = convert.task(task);
    }
    for (name, topic) in args.topics {
        convert = convert.topic_override(name, topic);
    }
    let mut opts = JobOptions::default()
        .convert(convert)
        .overwrite(args.overwrite)
        .file_size_mib(args.file_size_mib)
        .include_failures(args.include_failures)
        .unlabeled(match args.unlabeled {
            None => Unlabeled::Refuse,
            Some(UnlabeledArg::Keep) => Unlabeled::Keep,
            Some(UnlabeledArg::Skip) => Unlabeled::Skip,
        });
    if let Some(jobs) = args.jobs {
        opts = opts.jobs(jobs);
    }
    if let Some((i, n)) = args.shard {
        opts = opts.shard(i, n);
    }
    if let Some(gap) = args.split_gap {
        opts = opts.split_gap(gap);
    }
    if let Some(dir) = args.work_dir {
        opts = opts.work_dir(dir);
    }
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} episodes {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let frames = AtomicU64::new(0);
    let start = Instant::now();
    let results = scaledp_converter::run_inputs(&inputs, &out, &opts, &|p| match p {
        Progress::Total(n) => bar.set_length(n as u64),
        Progress::Done {
            result, frames: f, ..
        } => {
            if let InputResult::Failed(e) = result {
                bar.suspend(|| eprintln!("error: {}", e.one_line()));
            }
            let total = frames.fetch_add(f as u64, Ordering::Relaxed) + f as u64;
            bar.set_message(format!(
                "{total} frames, {:.0} frames/s",
                total as f64 / start.elapsed().as_secs_f64()
            ));
            bar.inc(1);
        }
    })?;
    bar.finish_and_clear();
    summarize(&results, &out, start.elapsed().as_secs_f64())
}

fn summarize(
    results: &[(PathBuf, InputResult)],
    out: &Location,
    seconds: f64,
) -> Result<ExitStatus> {
    let (mut converted, mut frames, mut skipped, mut failed) = (0, 0, 0, Vec::new());
    for (path, o) in results {
        match o {
            InputResult::Converted(recs) => {
                for rec in recs {
                    converted += 1;
                    frames += rec.length;
                    let dropped: u64 = rec.report.streams.iter().map(|s| s.dropped).sum();
                    println!(
                    "episode {:>4}  {:>5} frames  skew {:>5.1} ms  invalid {:>3}  dropped {:>3}  {:<9}  {}",
                    rec.episode_index,
                    rec.length,
                    rec.report.max_camera_skew_s * 1e3,
                    rec.report.invalid,
                    dropped,
                    rec.recorded.label.as_deref().unwrap_or("-"),
                    rec.source
                );
                }
            }
            InputResult::Skipped(why) => {
                skipped += 1;
                eprintln!("skipped {}: {why}", path.display());
            }
            InputResult::Failed(e) => failed.push(e.one_line()),
        }
    }
    println!(
        "{converted} converted ({frames} frames, {:.0} frames/s), {skipped} skipped, {} failed → {}",
        frames as f64 / seconds.max(1e-9),
        failed.len(),
        out
    );
    for line in &failed {
        println!("failed: {line}");
    }
    Ok(if failed.is_empty() {
        ExitStatus::Success
    } else {
        ExitStatus::DataLost
    })
}

pub fn merge(args: MergeArgs) -> Result<ExitStatus> {
    let inputs = args
        .inputs
        .iter()
        .map(|p| location(p))
        .collect::<Result<Vec<_>>>()?;
    let out = location(&args.out)?;
    let mut opts = MergeOptions::default()
        .file_size_mib(args.file_size_mib)
        .skip_empty(args.skip_empty);
    if let Some(dir) = args.work_dir {
        opts = opts.work_dir(dir);
    }
    let summary = scaledp_converter::merge_datasets(&inputs, &out, &opts)?;
    for empty in &summary.empty {
        eprintln!("skipped {empty}: holds nothing (a shard without inputs?)");
    }
    println!(
        "{} episodes from {} datasets → {out}",
        summary.episodes,
        inputs.len() - summary.empty.len(),
    );
    Ok(ExitStatus::Success)
}
