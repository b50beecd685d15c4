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
    /// Episodes recorded again because convert would have rejected them.
    pub rerecorded: u64,
}

impl Tally {
    /// Episodes kept: finished, not discarded, not moved to `discarded/` since.
    pub fn kept(&self) -> usize {
        self.kept_episodes().count()
    }
    /// The episodes [`Tally::kept`] counts, in order.
    pub fn kept_episodes(&self) -> impl Iterator<Item = &EpisodeReport> {
        self.finished
            .iter()
            .filter(|r| r.outcome != Label::Discarded && !self.moved.contains(&r.index))
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
/// each with `outcome`; stops early when `stop` is set. An episode `scaledp convert` would reject
/// is recorded again, at most `retries` times, as an operator does before the scene is reset:
/// the rejected file moves to `discarded/` and does not count.
pub fn timed_episodes(
    recorder: &Recorder,
    episodes: Option<u64>,
    duration_s: f64,
    outcome: Label,
    stop: &AtomicBool,
    labels: Vec<String>,
    retries: u64,
) -> Tally {
    let mut tally = Tally::default();
    let mut line = StatusLine::new(labels);
    let show = std::io::stderr().is_terminal();
    let (mut n, mut tries) = (0, 0);
    while episodes.is_none_or(|e| n < e) && !stop.load(Ordering::Relaxed) {
        let finished_before = tally.finished.len();
        recorder.send(if tries > 0 {
            Command::Rerecord
        } else {
            Command::Start
        });
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
        // An episode whose file cannot even be opened: the next would fail alike.
        if let Some(index) = tally.unstartable {
            eprintln!("stopping: episode {index} could not be written");
            break;
        }
        let rejected = tally.finished[finished_before..]
            .last()
            .filter(|r| !r.verdict.accepted);
        match rejected {
            Some(r) if tries < retries && !stop.load(Ordering::Relaxed) => {
                tries += 1;
                tally.rerecorded += 1;
                eprintln!(
                    "episode {}: convert would reject it; recording it again ({tries} of {retries})",
                    r.index
                );
            }
            _ => {
                n += 1;
                tries = 0;
            }
        }
    }
    tally
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
    use std::sync::Arc;
    use std::time::Duration;

    use scaledp_recorder::{net, Label, RecorderOptions};
    use scaledp_schema::Rig;
    use scaledp_sim::SimOptions;

    use super::{timed_episodes, wait_for_topics};

    /// The front camera stalls through the first episode (five frames held 300 ms each), so
    /// convert would reject it: the session records it again, moves the rejected file to
    /// `discarded/` and keeps one episode, within the retries allowed.
    #[test]
    fn an_episode_convert_would_reject_is_recorded_again_and_moved_aside() {
        let rig = Rig::builtin("franka_2zed")
            .unwrap()
            .with_image_size(32, 24)
            .training_streams();
        let camera = rig.cameras[0].topic.trim_start_matches('/').to_string();
        let endpoint = format!("tcp/127.0.0.1:{}", crate::shared::free_port().unwrap());
        let sim_session =
            net::open(net::zenoh_config(None, &[], std::slice::from_ref(&endpoint)).unwrap())
                .unwrap();
        let armed = Arc::new(AtomicBool::new(false));
        let stalls = Arc::new(AtomicU32::new(5));
        let (on, left) = (armed.clone(), stalls.clone());
        let sim = SimOptions::new(rig.clone())
            .seed(1)
            .on_publish(Arc::new(move |topic, _| {
                if topic.contains(&camera)
                    && on.load(Ordering::Relaxed)
                    && left
                        .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| n.checked_sub(1))
                        .is_ok()
                {
                    std::thread::sleep(Duration::from_millis(300));
                }
            }))
            .spawn(&sim_session)
            .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let recorder = RecorderOptions::new(rig, dir.path())
            .control_prefix(format!("test/session/{}", std::process::id()))
            .start(net::zenoh_config(None, &[endpoint], &[]).unwrap())
            .unwrap();
        let stop = AtomicBool::new(false);
        wait_for_topics(&recorder, 15.0, &stop);
        armed.store(true, Ordering::Relaxed);
        let tally = timed_episodes(&recorder, Some(1), 1.5, Label::Success, &stop, vec![], 2);
        recorder.finish().unwrap();
        sim.stop();
        let _ = zenoh::Wait::wait(sim_session.close());

        assert_eq!(
            stalls.load(Ordering::Relaxed),
            0,
            "the camera never stalled"
        );
        let first = &tally.finished[0];
        assert!(!first.verdict.accepted, "{}", first.verdict.line());
        assert!((1..=2).contains(&tally.rerecorded), "{tally:?}");
        assert_eq!(tally.finished.len() as u64, tally.rerecorded + 1);
        assert_eq!(tally.kept(), 1, "{tally:?}");
        let kept = tally.kept_episodes().next().unwrap();
        assert_eq!(kept.index, tally.rerecorded);
        let files = |d: &std::path::Path| std::fs::read_dir(d).map_or(0, |r| r.count());
        assert_eq!(
            files(&dir.path().join("discarded")) as u64,
            tally.rerecorded
        );
        assert!(kept.summary.path.is_file());
        assert!(
            !first.summary.path.exists(),
            "the rejected file was not moved"
        );
    }
}
