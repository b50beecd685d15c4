//! `scaledp record`: episodes from the keyboard, from a Zenoh control key, or on a timer.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Result;
use crossterm::event::{self, Event as TermEvent, KeyCode, KeyEvent, KeyModifiers};
use scaledp_recorder::{Command, Label, Recorder, RecorderOptions, TopicPattern};
use scaledp_schema::msg::MsgSearch;
use scaledp_schema::rig::ExtraTopic;
use scaledp_schema::Rig;

use crate::cli::{ExitStatus, RecordArgs};
use crate::shared::{self, drain, timed_episodes, wait_for_topics, Tally};
use crate::ui::{topic_labels, StatusLine};

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
    let recorder = RecorderOptions::new(rig.clone(), &args.out)
        .task(&args.task)
        .operator(operator)
        .compression(shared::compression(args.compression))
        .chunk_size(args.chunk_mib << 20)
        .queue_bytes(args.queue_mib << 20)
        .control_prefix(&args.control_prefix)
        .bridge_namespace(&args.namespace)
        .msg_search(msg_search(&args)?);
    let recorder = patterns
        .into_iter()
        .fold(recorder, RecorderOptions::topic_pattern)
        .start(config)?;
    if let Some(url) = &args.view {
        shared::viewer::live::start(&recorder, &rig, &args.namespace, url.as_deref())?;
    }
    let stop = shared::interrupt_flag();
    let tally = if let Some(duration) = args.duration {
        wait_for_topics(&recorder, args.wait_topics, &stop);
        timed_episodes(
            &recorder,
            args.episodes,
            duration,
            Label::Unlabeled,
            &stop,
            labels,
        )
    } else if !args.no_keyboard && std::io::stdin().is_terminal() {
        keyboard(&recorder, args.episodes, &stop, labels)?
    } else {
        tracing::info!(
            "waiting for commands on {}/control",
            args.control_prefix.trim_matches('/')
        );
        controlled(&recorder, args.episodes, &stop, labels)
    };
    if let Err(e) = shared::viewer::live::finish() {
        tracing::warn!("live view: {e:#}");
    }
    recorder.finish()?;
    let lost = tally.lost();
    eprintln!(
        "{} episodes recorded in {}, {} failed, {lost} messages lost",
        tally.finished.len(),
        args.out.display(),
        tally.failed
    );
    Ok(tally.exit_status())
}

/// Episodes driven only by the Zenoh control key (or Ctrl-C).
fn controlled(
    recorder: &Recorder,
    episodes: Option<u64>,
    stop: &AtomicBool,
    labels: Vec<String>,
) -> Tally {
    let mut tally = Tally::default();
    let mut line = StatusLine::new(labels);
    let show = std::io::stderr().is_terminal();
    let mut last_draw = Instant::now();
    while recorder.is_running() && !stop.load(Ordering::Relaxed) {
        drain(recorder, &mut tally, "\n");
        if episodes.is_some_and(|n| tally.finished.len() as u64 + tally.failed >= n) {
            break;
        }
        if show && last_draw.elapsed() > Duration::from_millis(250) {
            eprint!("\r\x1b[2K{}", line.render(recorder.status()));
            last_draw = Instant::now();
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    recorder.send(Command::Quit);
    let deadline = Instant::now() + Duration::from_secs(60);
    while recorder.is_running() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    drain(recorder, &mut tally, "\n");
    tally
}

const KEYS_HELP: &str = "[space] start/stop  [y] success  [n] failure  [d] discard  [q] quit";

/// Restores the terminal however the keyboard loop ends.
struct RawMode;
impl Drop for RawMode {
    fn drop(&mut self) {
        let _ = crossterm::terminal::disable_raw_mode();
        eprintln!();
    }
}

/// Episodes driven from the keyboard, with a live status line; the Zenoh control key works too.
fn keyboard(
    recorder: &Recorder,
    episodes: Option<u64>,
    stop: &AtomicBool,
    labels: Vec<String>,
) -> Result<Tally> {
    eprintln!("{KEYS_HELP}");
    crossterm::terminal::enable_raw_mode()?;
    let _guard = RawMode;
    let mut tally = Tally::default();
    let mut line = StatusLine::new(labels);
    let eol = "\r\n";
    while recorder.is_running() && !stop.load(Ordering::Relaxed) {
        if drain(recorder, &mut tally, eol) {
            eprint!("{KEYS_HELP}{eol}");
        }
        if episodes.is_some_and(|n| tally.finished.len() as u64 + tally.failed >= n) {
            break;
        }
        eprint!("\r\x1b[2K{}", line.render(recorder.status()));
        if !event::poll(Duration::from_millis(250))? {
            continue;
        }
        let TermEvent::Key(KeyEvent {
            code, modifiers, ..
        }) = event::read()?
        else {
            continue;
        };
        let cmd = match code {
            KeyCode::Char('c') if modifiers.contains(KeyModifiers::CONTROL) => Command::Quit,
            KeyCode::Char(' ') | KeyCode::Enter => Command::Toggle,
            KeyCode::Char('y') => Command::Stop(Label::Success),
            KeyCode::Char('n') => Command::Stop(Label::Failure),
            KeyCode::Char('d') => Command::Stop(Label::Discarded),
            KeyCode::Char('q') | KeyCode::Esc => Command::Quit,
            _ => continue,
        };
        let quit = cmd == Command::Quit;
        recorder.send(cmd);
        if quit {
            break;
        }
    }
    recorder.send(Command::Quit);
    let deadline = Instant::now() + Duration::from_secs(60);
    while recorder.is_running() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    drain(recorder, &mut tally, eol);
    Ok(tally)
}
