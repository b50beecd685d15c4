//! `scaledp record`: episodes from the keyboard, from a Zenoh control key, or on a timer.

use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Result;
use crossterm::event::{self, Event as TermEvent, KeyCode, KeyEvent, KeyModifiers};
use scaledp_recorder::{Command, EpisodeReport, Event, Label, Recorder, RecorderOptions};
use scaledp_schema::Rig;

use crate::cli::{ExitStatus, RecordArgs};
use crate::ui::{topic_labels, StatusLine};

/// Episodes finished and problems seen during a session.
#[derive(Debug, Default)]
pub struct Tally {
    /// Finished episodes, in order.
    pub finished: Vec<EpisodeReport>,
    /// Episodes that failed.
    pub failed: u64,
    /// Episodes whose file was opened.
    started: Vec<u64>,
    /// An episode failed before its file could be opened (the output cannot be written).
    unstartable: Option<u64>,
}

impl Tally {
    /// Messages lost over the session (queue drops and upstream gaps).
    pub fn lost(&self) -> u64 {
        self.finished
            .iter()
            .map(|r| r.dropped.values().sum::<u64>() + r.upstream_gaps.values().sum::<u64>())
            .sum()
    }
    fn exit_status(&self) -> ExitStatus {
        if self.failed > 0 || self.lost() > 0 {
            ExitStatus::DataLost
        } else {
            ExitStatus::Success
        }
    }
}

/// One line per finished episode, on stdout.
fn print_finished(r: &EpisodeReport, eol: &str) {
    let msgs: u64 = r.summary.messages.values().sum();
    let lost: u64 = r.dropped.values().sum::<u64>() + r.upstream_gaps.values().sum::<u64>();
    print!(
        "{}\t{}\t{:.1} s\t{msgs} messages\t{lost} lost{eol}",
        r.summary.path.display(),
        r.outcome,
        r.duration_s
    );
    let _ = std::io::stdout().flush();
}

/// Handles pending events; returns true when an episode finished or failed.
fn drain(recorder: &Recorder, tally: &mut Tally, eol: &str) -> bool {
    let mut ended = false;
    super::view::live::update(recorder, None);
    while let Ok(ev) = recorder.events().try_recv() {
        super::view::live::update(recorder, Some(&ev));
        match ev {
            Event::Started { index, path } => {
                tracing::debug!(index, path = %path.display(), "started");
                tally.started.push(index);
            }
            Event::Finished(r) => {
                print_finished(&r, eol);
                tally.finished.push(r);
                ended = true;
            }
            Event::Failed { index, error } => {
                eprint!("episode {index} failed: {error}{eol}");
                tally.failed += 1;
                if !tally.started.contains(&index) {
                    tally.unstartable = Some(index);
                }
                ended = true;
            }
        }
    }
    ended
}

/// Waits (at most `timeout_s`) until every topic has delivered a message; warns about the rest.
pub fn wait_for_topics(recorder: &Recorder, timeout_s: f64, stop: &AtomicBool) {
    let start = Instant::now();
    loop {
        let status = recorder.status();
        let silent: Vec<_> = status
            .topics
            .iter()
            .filter(|t| t.received == 0)
            .map(|t| t.topic.clone())
            .collect();
        if silent.is_empty() {
            return;
        }
        if start.elapsed().as_secs_f64() >= timeout_s || stop.load(Ordering::Relaxed) {
            tracing::warn!(
                "starting although no message arrived yet on: {}",
                silent.join(", ")
            );
            return;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Records `episodes` episodes of `duration_s` each (unbounded when `episodes` is None), ending
/// each with `outcome`; stops early when `stop` is set.
pub fn timed_episodes(
    recorder: &Recorder,
    episodes: Option<u64>,
    duration_s: f64,
    outcome: Label,
    stop: &AtomicBool,
    labels: Vec<String>,
) -> Tally {
    let mut tally = Tally::default();
    let mut line = StatusLine::new(labels);
    let show = std::io::stderr().is_terminal();
    let mut n = 0;
    while episodes.is_none_or(|e| n < e) && !stop.load(Ordering::Relaxed) {
        recorder.send(Command::Start);
        let start = Instant::now();
        // An episode that fails while being written (a full disk) is over: no stop to wait for.
        let mut ended = false;
        while start.elapsed().as_secs_f64() < duration_s && !stop.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(100));
            ended |= drain(recorder, &mut tally, "\n");
            if ended {
                break;
            }
            if show {
                eprint!("\r\x1b[2K{}", line.render(recorder.status()));
            }
        }
        if !ended {
            recorder.send(Command::Stop(outcome));
            let deadline = Instant::now() + Duration::from_secs(60);
            while !drain(recorder, &mut tally, "\n") && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(20));
            }
        }
        if show {
            eprint!("\r\x1b[2K");
        }
        n += 1;
        // An episode whose file cannot even be opened: the next would fail alike.
        if let Some(index) = tally.unstartable {
            eprintln!("stopping: episode {index} could not be written");
            break;
        }
    }
    tally
}

pub fn run(args: RecordArgs) -> Result<ExitStatus> {
    let rig = Rig::load_or_builtin(&args.rig)?;
    let labels = topic_labels(&rig);
    let config = super::zenoh_config(&args.net, &[])?;
    let operator = args
        .operator
        .clone()
        .or_else(|| std::env::var("USER").ok())
        .unwrap_or_default();
    let recorder = RecorderOptions::new(rig.clone(), &args.out)
        .task(&args.task)
        .operator(operator)
        .compression(super::compression(args.compression))
        .chunk_size(args.chunk_mib << 20)
        .queue_bytes(args.queue_mib << 20)
        .control_prefix(&args.control_prefix)
        .bridge_namespace(&args.namespace)
        .start(config)?;
    if let Some(url) = &args.view {
        super::view::live::start(&recorder, &rig, &args.namespace, url.as_deref())?;
    }
    let stop = super::interrupt_flag();
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
    if let Err(e) = super::view::live::finish() {
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
        recorder.send(cmd);
        if cmd == Command::Quit {
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
