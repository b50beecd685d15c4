//! `scaledp demo`: the simulated rig and the recorder in one process, over loopback.

use std::collections::BTreeMap;

use anyhow::Result;
use scaledp_recorder::{net, Outcome, RecorderOptions};
use scaledp_schema::Rig;

use super::record::{timed_episodes, wait_for_topics};
use crate::cli::{DemoArgs, ExitStatus};
use crate::sim::SimOptions;
use crate::ui::topic_labels;

pub fn run(args: DemoArgs) -> Result<ExitStatus> {
    let rig = Rig::load_or_builtin(&args.rig)?;
    let endpoint = format!("tcp/127.0.0.1:{}", super::free_port()?);
    eprintln!(
        "simulating rig '{}' on {endpoint}; recording {} episodes of {} s",
        rig.name, args.episodes, args.duration
    );
    let sim_session = net::open(net::zenoh_config(
        None,
        &[],
        std::slice::from_ref(&endpoint),
    )?)?;
    let sim = SimOptions::new(rig.clone())
        .seed(args.seed)
        .spawn(&sim_session)?;
    let out = args.out.join("recordings");
    let recorder = RecorderOptions::new(rig.clone(), &out)
        .task("pick up the red cube and put it down to the side")
        .operator("scaledp demo")
        .start(net::zenoh_config(None, &[endpoint], &[])?)?;
    let stop = super::interrupt_flag();
    wait_for_topics(&recorder, 15.0, &stop);
    let tally = timed_episodes(
        &recorder,
        Some(args.episodes),
        args.duration,
        Outcome::Success,
        &stop,
        topic_labels(&rig),
    );
    recorder.finish()?;
    sim.stop();
    let _ = zenoh::Wait::wait(sim_session.close());

    let mut per_topic: BTreeMap<&str, (u64, u64, u64)> = BTreeMap::new();
    let seconds: f64 = tally.finished.iter().map(|r| r.duration_s).sum();
    for r in &tally.finished {
        for (topic, n) in &r.summary.messages {
            let e = per_topic.entry(topic).or_default();
            e.0 += n;
            e.1 += r.summary.bytes[topic];
            e.2 += r.dropped[topic] + r.upstream_gaps[topic];
        }
    }
    println!(
        "\n{} episodes, {seconds:.1} s in all, in {}",
        tally.finished.len(),
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
    Ok(if tally.lost() > 0 || tally.failed > 0 {
        ExitStatus::DataLost
    } else {
        ExitStatus::Success
    })
}
