//! `scaledp record`: episodes from the keyboard, from a Zenoh control key, or on a timer
//! (attended, with a reset between episodes, or unattended).

use std::io::IsTerminal;

use anyhow::Result;
use scaledp_recorder::{Plan, RecorderOptions, TopicPattern};
use scaledp_schema::msg::MsgSearch;
use scaledp_schema::rig::ExtraTopic;
use scaledp_schema::Rig;

use crate::cli::{ExitStatus, RecordArgs};
use crate::shared::attend::{self, Attended};
use crate::shared::{self, wait_for_topics};
use crate::ui::topic_labels;

/// The rig with `--remap` applied and every concrete `--topic NAME:TYPE` among its further
/// topics (so the stored rig lists it); the `--topic` globs and untyped names left to match
/// while recording.
fn rig_and_patterns(args: &RecordArgs) -> Result<(Rig, Vec<TopicPattern>)> {
    let mut rig = Rig::load_or_builtin(&args.rig)?;
    for (from, to) in &args.remap {
        rig.remap(from, to)?;
    }
    let mut patterns = Vec::new();
    for p in &args.topics {
        match (p.is_glob(), p.message_type()) {
            (false, Some(ty)) => {
                if rig.topics().iter().any(|t| t.topic == p.name()) {
                    tracing::info!("--topic {p}: already a topic of rig {}", rig.name);
                    continue;
                }
                rig.extra_topics.push(ExtraTopic {
                    name: p.name().to_string(),
                    message_type: ty.to_string(),
                    rate_hz: None,
                    latched: false,
                });
            }
            _ => patterns.push(p.clone()),
        }
    }
    Ok((rig, patterns))
}

/// Where definitions of unknown types are looked up: `AMENT_PREFIX_PATH`, then `--msg-path`.
fn msg_search(args: &RecordArgs) -> Result<MsgSearch> {
    let mut search =
        MsgSearch::new().ament_prefix_path(&std::env::var("AMENT_PREFIX_PATH").unwrap_or_default());
    for dir in &args.msg_path {
        anyhow::ensure!(
            dir.is_dir(),
            "--msg-path {}: no such directory",
            dir.display()
        );
        search = search.dir(dir);
    }
    Ok(search)
}

/// Runs `scaledp record`.
pub fn run(args: RecordArgs) -> Result<ExitStatus> {
    let (rig, patterns) = rig_and_patterns(&args)?;
    let labels = topic_labels(&rig);
    let config = shared::zenoh_config(&args.net, &[])?;
    let operator = args
        .operator
        .clone()
        .or_else(|| std::env::var("USER").ok())
        .unwrap_or_default();
    let unattended = args.duration.is_some();
    let keyboard = !unattended && !args.no_keyboard && std::io::stdin().is_terminal();
    let recorder = RecorderOptions::new(rig.clone(), &args.out)
        .tasks(args.task.iter().cloned())
        .operator(operator)
        .compression(shared::compression(args.compression))
        .chunk_size(args.chunk_mib << 20)
        .queue_bytes(args.queue_mib << 20)
        .control_prefix(&args.control_prefix)
        .bridge_namespace(&args.namespace)
        .msg_search(msg_search(&args)?)
        .check_topics(keyboard)
        .episode_time(args.episode_time.or(args.duration))
        .disk_guard(!args.no_disk_guard)
        .disk_warn_minutes(args.disk_warn_minutes);
    let recorder = patterns
        .into_iter()
        .fold(recorder, RecorderOptions::topic_pattern)
        .start(config)?;
    if let Some(url) = &args.view {
        shared::viewer::live::start(&recorder, &rig, &args.namespace, url.as_deref())?;
    }
    let stop = shared::interrupt_flag();
    let plan = Plan {
        episodes: args.episodes,
        episode_s: args.duration.or(args.episode_time),
        reset_s: if unattended { 0.0 } else { args.reset_time },
        attended: !unattended,
        confirm: keyboard,
    };
    if unattended {
        wait_for_topics(&recorder, args.wait_topics, &stop);
    } else if !keyboard {
        tracing::info!(
            "waiting for commands on {}/control",
            args.control_prefix.trim_matches('/')
        );
    }
    let how = Attended {
        keyboard,
        tasks: &args.task,
        stop: &stop,
        labels,
    };
    let tally = attend::run(&recorder, plan, how);
    if let Err(e) = shared::viewer::live::finish() {
        tracing::warn!("live view: {e:#}");
    }
    recorder.finish()?;
    let tally = tally?;
    let lost = tally.lost();
    eprintln!(
        "{} episodes recorded in {}, {} failed, {lost} messages lost; {} kept",
        tally.finished.len(),
        args.out.display(),
        tally.failed,
        tally.kept()
    );
    match (&tally.stopped, tally.exit_status()) {
        (Some(why), status) => {
            eprintln!("stopped: {why}");
            Ok(match status {
                ExitStatus::Success => ExitStatus::Error,
                other => other,
            })
        }
        (None, status) => Ok(status),
    }
}
