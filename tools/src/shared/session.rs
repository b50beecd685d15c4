//! What recording sessions share: the tally of finished and failed episodes, draining the
//! recorder's events (printing finished episodes, feeding the live view), waiting for topics,
//! and episodes on a timer.

use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use scaledp_recorder::{Command, EpisodeReport, Event, Label, Recorder};

use super::viewer;
use crate::cli::ExitStatus;
use crate::ui::StatusLine;

/// Episodes finished and problems seen during a session.
#[derive(Debug, Default)]
pub struct Tally {
    /// Finished episodes, in order.
    pub finished: Vec<EpisodeReport>,
    /// Episodes that failed.
    pub failed: u64,
    /// Episodes whose file was opened.
    pub started: Vec<u64>,
    /// An episode failed before its file could be opened (the output cannot be written).
    pub unstartable: Option<u64>,
    /// Finished episodes moved to `discarded/` afterwards (a discard or re-record after a label).
    pub moved: Vec<u64>,
    /// Episodes that ended held for a decision (their verdict was said then).
    pub held: Vec<u64>,
    /// The last refusal said.
    pub last_refusal: Option<String>,
    /// Why the session ended before its plan did.
    pub stopped: Option<String>,
}

impl Tally {
    /// Episodes kept: finished, not discarded, not moved to `discarded/` since.
    pub fn kept(&self) -> usize {
        self.finished
            .iter()
            .filter(|r| r.outcome != Label::Discarded && !self.moved.contains(&r.index))
            .count()
    }
    /// Messages lost over the session (queue drops and upstream gaps).
    pub fn lost(&self) -> u64 {
        self.finished
            .iter()
            .map(|r| r.dropped.values().sum::<u64>() + r.upstream_gaps.values().sum::<u64>())
            .sum()
    }
    /// Exit code of the session: data lost when an episode failed or messages were lost.
    pub fn exit_status(&self) -> ExitStatus {
        if self.failed > 0 || self.lost() > 0 {
            ExitStatus::DataLost
        } else {
            ExitStatus::Success
        }
    }
}

/// One line per finished episode, on stdout.
pub fn print_finished(r: &EpisodeReport, eol: &str) {
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
pub fn drain(recorder: &Recorder, tally: &mut Tally, eol: &str) -> bool {
    viewer::live::update(recorder, None);
    let mut ended = false;
    while let Ok(ev) = recorder.events().try_recv() {
        ended |= show(recorder, &ev, tally, eol);
    }
    ended
}

/// Counts one event, feeds it to the live view and prints what the operator reads of it: a line
/// on stdout per finished episode, its verdict and what went wrong on stderr. Returns true when
/// an episode finished or failed.
pub fn show(recorder: &Recorder, ev: &Event, tally: &mut Tally, eol: &str) -> bool {
    viewer::live::update(recorder, Some(ev));
    match ev {
        Event::Started { index, path } => {
            tracing::debug!(index, path = %path.display(), "started");
            tally.started.push(*index);
            tally.last_refusal = None;
            false
        }
        Event::Ended { index, verdict } => {
            tally.held.push(*index);
            eprint!("episode {index} ended, {}{eol}", verdict.line());
            false
        }
        Event::Finished(r) => {
            print_finished(r, eol);
            // Said at its end already when it was held.
            if !tally.held.contains(&r.index) {
                eprint!("episode {}: {}{eol}", r.index, r.verdict.line());
            }
            if let Some(cut) = &r.cut {
                eprint!("{cut}{eol}");
            }
            tally.finished.push(r.clone());
            true
        }
        Event::Failed { index, error } => {
            eprint!("episode {index} failed: {error}{eol}");
            tally.failed += 1;
            if !tally.started.contains(index) {
                tally.unstartable = Some(*index);
            }
            true
        }
        Event::Discarded { index, path } => {
            tally.moved.push(*index);
            eprint!("episode {index} moved to {}{eol}", path.display());
            false
        }
        Event::Refused { reason, .. } => {
            // A refusal repeated while nothing changes is said once.
            if tally.last_refusal.as_ref() != Some(reason) {
                eprint!("{reason}{eol}");
                tally.last_refusal = Some(reason.clone());
            }
            false
        }
        Event::Task(task) => {
            eprint!("task of the next episodes: {task}{eol}");
            false
        }
        Event::DiskLow(line) => {
            eprint!("{line}{eol}");
            false
        }
    }
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
