//! `scaledp sim`: a simulated rig on Zenoh that follows commands; with `--operator scripted`, the
//! scripted teleoperator demonstrates the task (episode after episode, or `--episodes N` of them
//! around a recorder's control key, or `--score` in simulated time).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Result;
use scaledp_schema::Rig;
use scaledp_sim::{KeyStyle, Pedal, Scene, Sim, SimOptions};

use crate::cli::{ExitStatus, KeysArg, OperatorArg, SimArgs};
use crate::shared::{self, wilson_interval, Successes};

pub fn run(args: SimArgs) -> Result<ExitStatus> {
    let mut rig = Rig::load_or_builtin(&args.rig)?;
    if let Some(codec) = args.camera_codec {
        codec.apply(&mut rig);
    }
    let scripted = args.operator == OperatorArg::Scripted;
    if args.score {
        anyhow::ensure!(
            scripted,
            "--score scores the scripted operator: add --operator scripted"
        );
        return score(
            &rig,
            args.seed,
            args.episodes.unwrap_or(100),
            args.max_seconds,
        );
    }
    anyhow::ensure!(
        scripted || args.episodes.is_none(),
        "--episodes needs --operator scripted"
    );
    let config = shared::zenoh_config(
        &args.net,
        &[scaledp_recorder::net::DEFAULT_ENDPOINT.to_string()],
    )?;
    let session = scaledp_recorder::net::open(config)?;
    let keys = match args.keys {
        KeysArg::Bridge => KeyStyle::Bridge,
        KeysArg::Rmw => KeyStyle::Rmw,
    };
    tracing::info!(rig = %rig.name, seed = args.seed, "simulating {} topics", rig.topics().len());
    if rig.simulator.is_some() {
        anyhow::ensure!(
            args.episodes.is_none(),
            "--episodes records a recorder's episodes around the built-in cell; for {} use `scaledp collect --rig {}`",
            rig.name,
            rig.name
        );
        let stop = shared::interrupt_flag();
        return bridge(rig, &args, keys, scripted, &session, &stop);
    }
    let sim = SimOptions::new(rig)
        .seed(args.seed)
        .keys(keys)
        .namespace(args.namespace.clone())
        .scripted_operator(scripted)
        .autoplay(scripted && args.episodes.is_none())
        .control_prefix(&args.sim_prefix)
        .spawn(&session)?;
    let stop = shared::interrupt_flag();
    let status = match args.episodes {
        Some(n) if scripted => episodes(&sim, &session, &args, n, &stop)?,
        _ => {
            let start = Instant::now();
            while !stop.load(Ordering::Relaxed)
                && args
                    .duration
                    .is_none_or(|d| start.elapsed().as_secs_f64() < d)
            {
                std::thread::sleep(Duration::from_millis(50));
            }
            ExitStatus::Success
        }
    };
    for (topic, n) in sim.stop() {
        println!("{topic}\t{n} messages published");
    }
    Ok(status)
}

/// The operator's success rate over `n` seeds in simulated time (no cameras, no network).
fn score(rig: &Rig, seed: u64, n: u64, max_s: f64) -> Result<ExitStatus> {
    let scene = std::sync::Arc::new(Scene::new(rig));
    let start = Instant::now();
    let mut tally = Successes::default();
    for s in seed..seed + n {
        let r = scaledp_sim::headless::run_on(scene.clone(), s, max_s);
        tally.add(&r.task, r.duration_s);
        if !r.task.success {
            println!("seed {s}\tfailure\t{:.1} s", r.duration_s);
        }
    }
    let (lo, hi) = wilson_interval(tally.successes, tally.episodes);
    println!(
        "scripted operator on {}: {}/{} successes ({:.1} %, 95 % Wilson interval {:.1}–{:.1} %) over seeds {seed}..{}, \
         mean time to success {:.2} s, mean episode {:.2} s ({:.0} ms of simulation each)",
        rig.name,
        tally.successes,
        tally.episodes,
        tally.rate() * 100.0,
        lo * 100.0,
        hi * 100.0,
        seed + n - 1,
        tally.mean_time_to_success_s(),
        tally.mean_duration_s(),
        start.elapsed().as_secs_f64() * 1e3 / n.max(1) as f64
    );
    Ok(ExitStatus::Success)
}

/// `n` operator episodes, each started and ended on a recorder's control key like a pedal.
fn episodes(
    sim: &Sim,
    session: &zenoh::Session,
    args: &SimArgs,
    n: u64,
    stop: &AtomicBool,
) -> Result<ExitStatus> {
    let pedal = Pedal::new(session, &args.control_prefix)?;
    let recorder = pedal.wait_for_recorder(Duration::from_secs_f64(args.wait_recorder));
    if !recorder {
        tracing::warn!(
            "no recorder listens on {}/control: demonstrating without recording",
            args.control_prefix.trim_matches('/')
        );
    }
    let mut tally = Successes::default();
    let started = Instant::now();
    for i in 0..n {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        let seed = args.seed + i;
        let r = sim.run_episode(
            seed,
            0.5,
            args.max_seconds,
            &mut || {
                let wait = if recorder { 5.0 } else { 0.0 };
                if pedal
                    .press("start", &["started"], Duration::from_secs_f64(wait))
                    .is_none()
                    && recorder
                {
                    tracing::warn!("the recorder did not report a started episode");
                }
            },
            stop,
        );
        // Let the last frames of the finished scene reach the recorder.
        std::thread::sleep(Duration::from_millis(300));
        let word = if r.task.success { "success" } else { "failure" };
        let wait = Duration::from_secs(if recorder { 30 } else { 0 });
        let path = pedal
            .press(word, &["finished", "failed"], wait)
            .and_then(|v| v["path"].as_str().map(str::to_string))
            .unwrap_or_default();
        tally.add(&r.task, r.duration_s);
        println!("seed {seed}\t{word}\t{:.1} s\t{path}", r.duration_s);
    }
    println!(
        "{}/{} successes ({:.1} %) in {:.1} s per episode",
        tally.successes,
        tally.episodes,
        tally.rate() * 100.0,
        started.elapsed().as_secs_f64() / tally.episodes.max(1) as f64
    );
    Ok(ExitStatus::Success)
}

/// A bridge rig (`metaworld/<task>`) live: its simulator stepping on its own `/clock`, taking
/// commands (or, with the scripted operator, its expert demonstrating seed after seed, each
/// ended a fifth of a second after its success or at the simulator's last step).
fn bridge(
    rig: Rig,
    args: &SimArgs,
    keys: KeyStyle,
    expert: bool,
    session: &zenoh::Session,
    stop: &AtomicBool,
) -> Result<ExitStatus> {
    use scaledp_sim::bridge::live::{LiveBridge, LiveOptions, STALL};
    let mut o = LiveOptions::new(rig.clone());
    o.keys = keys;
    o.namespace = args.namespace.clone();
    o.control_prefix = args.sim_prefix.clone();
    o.seed = args.seed;
    o.expert = expert;
    let mut sim = LiveBridge::spawn(o, session)?;
    eprintln!(
        "{} live on the simulation's /clock{} (Ctrl-C stops)",
        rig.name,
        if expert {
            ", its scripted expert demonstrating"
        } else {
            ", following the command topics"
        }
    );
    let start = Instant::now();
    let (mut seed, mut last_line) = (args.seed, Instant::now());
    while !stop.load(Ordering::Relaxed)
        && args
            .duration
            .is_none_or(|d| start.elapsed().as_secs_f64() < d)
    {
        std::thread::sleep(Duration::from_millis(50));
        // A simulator that died or hung ends the command with its error, not silence.
        sim.check(STALL)?;
        let t = sim.task();
        let over = t.done || t.time_to_success_s.is_some_and(|s| t.t_s - s >= 0.2);
        if expert && over && t.seed == seed {
            println!(
                "seed {seed}\t{}\t{:.2} s simulated, {:.2}× real time",
                if t.time_to_success_s.is_some() {
                    "success"
                } else {
                    "failure"
                },
                t.t_s,
                t.real_time_factor
            );
            seed += 1;
            sim.reset(seed);
        }
        if !expert && last_line.elapsed() >= Duration::from_secs(5) {
            last_line = Instant::now();
            eprintln!(
                "seed {} step {} ({:.2} s simulated, {:.2}× real time){}",
                t.seed,
                t.step,
                t.t_s,
                t.real_time_factor,
                if t.time_to_success_s.is_some() {
                    ", success"
                } else {
                    ""
                }
            );
        }
    }
    sim.stop()?;
    Ok(ExitStatus::Success)
}
