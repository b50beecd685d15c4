//! `scaledp collect`: demonstrations in one process — the simulated task, the scripted
//! teleoperator (its leader commands travel over Zenoh like anyone's) and the recorder library
//! writing the same episode files as `scaledp record` — one episode per seed, each reset to its
//! seed and labelled success or failure by the task's scorer. `collect.jsonl` beside the
//! episodes maps each file to its seed, so an evaluation can hold those seeds out.

use std::io::Write;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use scaledp_recorder::{Command, Event, Label, RecorderOptions};
use scaledp_schema::Rig;
use scaledp_sim::{EpisodeLine, SimOptions};

use crate::cli::{CollectArgs, ExitStatus};
use crate::shared::{self, wait_for_topics, wilson_interval, Successes};

/// The task in words, for a rig with `arms` arms.
fn default_task(arms: usize) -> &'static str {
    if arms > 1 {
        "put the red cube on the green square and the blue cube on the yellow square"
    } else {
        "put the red cube on the green square"
    }
}

pub fn run(args: CollectArgs) -> Result<ExitStatus> {
    let mut rig = Rig::load_or_builtin(&args.rig)?;
    if let Some(codec) = args.camera_codec {
        codec.apply(&mut rig);
    }
    if rig.command_topics().is_empty() {
        tracing::warn!(
            "rig {} has no command topics: actions will be the next measured state",
            rig.name
        );
    }
    let task = args
        .task
        .clone()
        .unwrap_or_else(|| default_task(rig.arms.len()).to_string());
    // By default the session only listens on a free loopback port: nothing else joins it.
    let listen = [format!("tcp/127.0.0.1:{}", shared::free_port()?)];
    let config = shared::zenoh_config(&args.net, &listen)?;
    let recorder = RecorderOptions::new(rig.clone(), &args.out)
        .task(&task)
        .operator("scripted-expert")
        .compression(shared::compression(args.compression))
        .control_prefix(format!("scaledp/collect/{}", std::process::id()))
        .start(config)?;
    // The simulator publishes on the recorder's own session: same process, no socket between.
    let sim = SimOptions::new(rig.clone())
        .seed(args.seed)
        .scripted_operator(true)
        .spawn(recorder.session())?;
    let stop = shared::interrupt_flag();
    wait_for_topics(&recorder, 15.0, &stop);
    let manifest_path = args.out.join("collect.jsonl");
    let mut manifest = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&manifest_path)
        .with_context(|| format!("opening {}", manifest_path.display()))?;

    let bar = ProgressBar::new(args.episodes).with_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} episodes, eta {eta} {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let started = Instant::now();
    let (mut tally, mut lost, mut failed) = (Successes::default(), 0u64, 0u64);
    for i in 0..args.episodes {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        let seed = args.seed + i;
        let r = sim.run_episode(
            seed,
            0.5,
            args.max_seconds,
            &mut || recorder.send(Command::Start),
            &stop,
        );
        // Let the last frames of the finished scene reach the writer.
        std::thread::sleep(Duration::from_millis(300));
        let label = if r.task.success {
            Label::Success
        } else {
            Label::Failure
        };
        recorder.send(Command::Stop(label));
        let deadline = Instant::now() + Duration::from_secs(60);
        let mut path = None;
        while path.is_none() {
            let Some(left) = deadline.checked_duration_since(Instant::now()) else {
                break;
            };
            match recorder.events().recv_timeout(left) {
                Ok(Event::Finished(rep)) => {
                    lost +=
                        rep.dropped.values().sum::<u64>() + rep.upstream_gaps.values().sum::<u64>();
                    path = Some(rep.summary.path.display().to_string());
                }
                Ok(Event::Failed { index, error }) => {
                    bar.suspend(|| eprintln!("episode {index} failed: {error}"));
                    failed += 1;
                    break;
                }
                Ok(Event::Started { .. }) => {}
                Err(_) => break,
            }
        }
        tally.add(&r.task, r.duration_s);
        let line = EpisodeLine {
            episode: path.as_deref(),
            rig: &rig.name,
            seed,
            outcome: label.as_str(),
            duration_s: r.duration_s,
            time_to_success_s: r.task.time_to_success_s,
        };
        writeln!(manifest, "{}", line.to_json())?;
        bar.set_message(format!(
            "{} ok ({:.0} %), seed {seed} {} in {:.1} s",
            tally.successes,
            tally.rate() * 100.0,
            label.as_str(),
            r.duration_s
        ));
        bar.inc(1);
    }
    bar.finish_and_clear();
    recorder.finish()?;
    sim.stop();
    let wall = started.elapsed().as_secs_f64();
    let (lo, hi) = wilson_interval(tally.successes, tally.episodes);
    println!(
        "{} episodes of {} in {} (seeds {}..{}): {} successes ({:.1} %, 95 % Wilson {:.1}–{:.1} %), \
         mean episode {:.1} s, {:.1} s of wall time per episode, {lost} messages lost, {failed} episodes failed to write",
        tally.episodes,
        rig.name,
        args.out.display(),
        args.seed,
        args.seed + tally.episodes.saturating_sub(1),
        tally.successes,
        tally.rate() * 100.0,
        lo * 100.0,
        hi * 100.0,
        tally.mean_duration_s(),
        wall / tally.episodes.max(1) as f64
    );
    Ok(if lost > 0 || failed > 0 {
        ExitStatus::DataLost
    } else {
        ExitStatus::Success
    })
}
