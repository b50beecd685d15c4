//! `scaledp collect`: demonstrations in one process — the simulated task, the scripted
//! teleoperator (its leader commands travel over Zenoh like anyone's) and the recorder library
//! writing the same episode files as `scaledp record` — one episode per seed, each reset to its
//! seed and labelled success or failure by the task's scorer. `collect.jsonl` beside the
//! episodes maps each file to its seed, so an evaluation can hold those seeds out. A rig whose
//! simulator runs behind the bridge (`metaworld/<task>`) is demonstrated by the simulator's own
//! scripted expert, its commands and the observations they lead to published on the simulation's
//! clock (as fast as the simulator steps, not in real time).

use std::io::Write;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use scaledp_recorder::{now_ns, Command, Event, Label, RecorderOptions};
use scaledp_schema::Rig;
use scaledp_sim::bridge::episodes::{expert_episode, Publishers};
use scaledp_sim::bridge::Bridge;
use scaledp_sim::{EpisodeLine, KeyStyle, SimOptions};

use crate::cli::{CollectArgs, ExitStatus};
use crate::shared::{self, wait_for_topics, wilson_interval, Successes};

/// The task in words (the cube task, or a simulator's task by name).
fn default_task(rig: &Rig) -> String {
    scaledp_deploy::task_text(rig)
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
    let task = args.task.clone().unwrap_or_else(|| default_task(&rig));
    // By default a session only this process uses: nothing else joins it.
    let listen = [scaledp_recorder::net::PRIVATE_ENDPOINT.to_string()];
    let config = shared::zenoh_config(&args.net, &listen)?;
    let recorder = RecorderOptions::new(rig.clone(), &args.out)
        .task(&task)
        .operator("scripted-expert")
        .compression(shared::compression(args.compression))
        .control_prefix(format!("scaledp/collect/{}", std::process::id()))
        .start(config)?;
    let stop = shared::interrupt_flag();
    let mut source = if rig.simulator.is_some() {
        Source::bridge(&rig, &recorder)?
    } else {
        // The simulator publishes on the recorder's own session: same process, no socket.
        let sim = SimOptions::new(rig.clone())
            .seed(args.seed)
            .scripted_operator(true)
            .spawn(recorder.session())?;
        wait_for_topics(&recorder, 15.0, &stop);
        Source::Cell(sim)
    };
    let manifest_path = args.out.join("collect.jsonl");
    let mut manifest = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&manifest_path)
        .with_context(|| format!("opening {}", manifest_path.display()))?;
    // --successes N: as many seeds as it takes (at most 2N + 10) for N successful episodes.
    let (target, limit) = match args.successes {
        Some(n) => (n, 2 * n + 10),
        None => (args.episodes, args.episodes),
    };
    let bar = ProgressBar::new(target).with_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} {msg}, eta {eta}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let started = Instant::now();
    let (mut tally, mut lost, mut failed) = (Successes::default(), 0u64, 0u64);
    for i in 0..limit {
        let done = if args.successes.is_some() {
            tally.successes
        } else {
            tally.episodes
        };
        if stop.load(Ordering::Relaxed) || done >= target {
            break;
        }
        let seed = args.seed + i;
        let r = source.episode(seed, args.max_seconds, &recorder, &stop)?;
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
                Ok(_) => {}
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
        if args.successes.is_none() || r.task.success {
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    recorder.finish()?;
    let versions = source.finish();
    let wall = started.elapsed().as_secs_f64();
    let (lo, hi) = wilson_interval(tally.successes, tally.episodes);
    println!(
        "{} episodes of {} in {} (seeds {}..{}): {} successes ({:.1} %, 95 % Wilson {:.1}–{:.1} %), \
         mean episode {:.1} s, {:.1} s of wall time per episode, {lost} messages lost, {failed} episodes failed to write{versions}",
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
    if args.successes.is_some_and(|n| tally.successes < n) {
        eprintln!(
            "warning: {} successful episodes of the {} asked for",
            tally.successes, target
        );
    }
    Ok(if lost > 0 || failed > 0 {
        ExitStatus::DataLost
    } else {
        ExitStatus::Success
    })
}

/// Where the demonstrations come from: the built-in cell with its scripted teleoperator, or a
/// simulator behind the bridge with its own scripted expert.
enum Source {
    Cell(scaledp_sim::Sim),
    Bridge(Box<(Bridge, Publishers)>),
}

impl Source {
    fn bridge(rig: &Rig, recorder: &scaledp_recorder::Recorder) -> Result<Self> {
        let bridge = Bridge::spawn(rig)?;
        let pubs = Publishers::declare(recorder.session(), rig, KeyStyle::Bridge, "")?;
        Ok(Source::Bridge(Box::new((bridge, pubs))))
    }

    /// One episode of `seed`, recording from its start.
    fn episode(
        &mut self,
        seed: u64,
        max_s: f64,
        recorder: &scaledp_recorder::Recorder,
        stop: &std::sync::atomic::AtomicBool,
    ) -> Result<scaledp_sim::EpisodeResult> {
        match self {
            Source::Cell(sim) => Ok(sim.run_episode(
                seed,
                0.5,
                max_s,
                &mut || recorder.send(Command::Start),
                stop,
            )),
            Source::Bridge(b) => {
                let (bridge, pubs) = &mut **b;
                // Record from the very first message: wait until the episode is open.
                let mut start = || {
                    recorder.send(Command::Start);
                    let deadline = Instant::now() + Duration::from_secs(10);
                    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
                        if let Ok(Event::Started { .. }) = recorder.events().recv_timeout(left) {
                            break;
                        }
                    }
                };
                // Two tenths of a second after the first success, so the data shows it held.
                let tail = (0.2 / bridge.hello().step_s).ceil() as u64;
                let ep = expert_episode(bridge, pubs, seed, now_ns(), tail, &mut start, stop)?;
                Ok(scaledp_sim::EpisodeResult {
                    task: scaledp_sim::TaskState {
                        seed,
                        t_s: ep.duration_s,
                        success: ep.success,
                        time_to_success_s: ep.time_to_success_s,
                        cubes: Vec::new(),
                    },
                    operator_done: true,
                    duration_s: ep.duration_s,
                })
            }
        }
    }

    /// Stops the source; a bridge's simulator versions, for the summary line.
    fn finish(self) -> String {
        match self {
            Source::Cell(sim) => {
                sim.stop();
                String::new()
            }
            Source::Bridge(b) => {
                let v = &b.0.hello().versions;
                let list: Vec<String> = v.iter().map(|(k, v)| format!("{k} {v}")).collect();
                format!(" ({})", list.join(", "))
            }
        }
    }
}
