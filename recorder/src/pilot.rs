//! The course of a session over time, whoever steers it: timed episodes (`episode_s`) with a
//! reset between them (`reset_s`), the verdict of each episode before the next one starts, and
//! the count of the episodes kept. Keys and Zenoh control words act on the recorder directly;
//! the pilot follows from the recorder's events (an episode ended early, re-recorded, labelled
//! in the reset) and adds only what time asks for: the end of an episode when its time is up, the
//! start of the next when the reset is over and the rig's topics are live.
//!
//! In an attended session an episode ends held (`Command::End`) so it can still be labelled,
//! kept or discarded during the reset; with someone at the keyboard (`confirm`), one that
//! `scaledp convert` would reject holds the next start until the operator keeps it or records
//! it again.

use std::time::{Duration, Instant};

use crate::control::{Command, Label};
use crate::report::Event;
use crate::session::Recorder;

/// How often a start the recorder refused is tried again.
const RETRY: Duration = Duration::from_secs(1);

/// How a session runs.
#[derive(Debug, Clone, Default)]
pub struct Plan {
    /// End the session after this many episodes kept (discarded ones do not count; in an
    /// unattended session failed ones do, so a broken disk cannot loop forever).
    pub episodes: Option<u64>,
    /// Each episode ends after this many seconds.
    pub episode_s: Option<f64>,
    /// Seconds between an episode's end and the next start (only with `episode_s`).
    pub reset_s: f64,
    /// An operator is there: episodes end held for a label, the next starts only once the
    /// topics are live, and discarded episodes do not count.
    pub attended: bool,
    /// Someone at the keyboard answers: an episode convert would reject waits for keep or
    /// re-record before the next starts.
    pub confirm: bool,
}

/// Where a session is.
#[derive(Debug, Clone, PartialEq)]
pub enum Phase {
    /// Nothing to do until someone starts an episode.
    Idle,
    /// The next episode waits for the rig's topics (or for room on the disk): why.
    Waiting(String),
    /// Recording episode `index`, for `elapsed_s`, `left_s` to go on a timer.
    Recording {
        /// Episode index.
        index: u64,
        /// Seconds since it started.
        elapsed_s: f64,
        /// Seconds left of its time, in a timed session.
        left_s: Option<f64>,
    },
    /// Between episodes, `left_s` before the next starts; `held` ended and may be labelled.
    Reset {
        /// The episode that ended and waits for a label, keep or discard.
        held: Option<u64>,
        /// Seconds before the next start.
        left_s: f64,
    },
    /// Episode `index` would be rejected by convert: keep it or record it again.
    Decide {
        /// Episode index.
        index: u64,
        /// Convert's reason.
        reason: String,
    },
    /// The session is over.
    Done,
}

/// Drives a session along its [`Plan`].
#[derive(Debug)]
pub struct Pilot {
    plan: Plan,
    recording: Option<(u64, Instant)>,
    /// Time was up and the end was sent.
    ending: bool,
    /// The last episode, held, was kept.
    keep_sent: bool,
    held: Option<u64>,
    reset_until: Option<Instant>,
    decide: Option<(u64, String)>,
    waiting: Option<String>,
    retry_at: Option<Instant>,
    kept: u64,
    failed: u64,
    done: Option<String>,
    /// The session could not go on.
    stopped: Option<String>,
}

impl Pilot {
    /// A pilot for `plan`.
    pub fn new(plan: Plan) -> Self {
        Self {
            plan,
            recording: None,
            ending: false,
            keep_sent: false,
            held: None,
            reset_until: None,
            decide: None,
            waiting: None,
            retry_at: None,
            kept: 0,
            failed: 0,
            done: None,
            stopped: None,
        }
    }

    /// Episodes kept so far (finished, not discarded).
    pub fn kept(&self) -> u64 {
        self.kept
    }

    /// Why the session ended, once it has: its episodes recorded, or a start the disk refused
    /// in an unattended session.
    pub fn done(&self) -> Option<&str> {
        self.done.as_deref()
    }

    /// Why the session ended before its plan did: an unattended session's episode that could not
    /// be written, or a start the disk guard refused.
    pub fn stopped(&self) -> Option<&str> {
        self.stopped.as_deref()
    }

    fn timed(&self) -> bool {
        self.plan.episode_s.is_some()
    }

    /// What the operator asked for (a key): sent on to the recorder. `Keep` also settles a
    /// decision on an episode already finished.
    pub fn command(&mut self, recorder: &Recorder, cmd: Command) {
        if cmd == Command::Keep && self.held.is_none() {
            self.decide = None;
        }
        if matches!(
            cmd,
            Command::Start | Command::ForceStart | Command::Rerecord
        ) {
            // The operator's start wins over a decision, a reset and a wait.
            self.decide = None;
            self.retry_at = None;
        }
        recorder.send(cmd);
    }

    /// Follows the recorder's events, then does what time asks for. Returns the events, for
    /// the caller to show.
    pub fn poll(&mut self, recorder: &Recorder) -> Vec<Event> {
        let mut seen = Vec::new();
        while let Ok(e) = recorder.events().try_recv() {
            self.follow(&e);
            seen.push(e);
        }
        if !recorder.is_running() {
            self.done
                .get_or_insert_with(|| "the recorder stopped".into());
        }
        if self.done.is_none() {
            self.steer(recorder);
        }
        seen
    }

    fn after_episode(&mut self) {
        self.recording = None;
        self.ending = false;
        if self.timed() {
            self.reset_until =
                Some(Instant::now() + Duration::from_secs_f64(self.plan.reset_s.max(0.0)));
        }
    }

    fn follow(&mut self, e: &Event) {
        match e {
            Event::Started { index, .. } => {
                self.recording = Some((*index, Instant::now()));
                self.ending = false;
                self.held = None;
                self.decide = None;
                self.waiting = None;
                self.reset_until = None;
            }
            Event::Ended { index, verdict } => {
                self.after_episode();
                self.keep_sent = false;
                self.held = Some(*index);
                if self.plan.confirm {
                    self.decide = verdict.reason.clone().map(|r| (*index, r));
                }
            }
            Event::Finished(r) => {
                let was_recording = self.recording.is_some_and(|(i, _)| i == r.index);
                if was_recording {
                    self.after_episode();
                }
                if self.held == Some(r.index) {
                    self.held = None;
                    // Labelled, kept or discarded: decided.
                    self.decide = None;
                }
                if r.outcome != Label::Discarded {
                    self.kept += 1;
                    if was_recording && self.plan.confirm && r.cut.is_none() {
                        self.decide = r.verdict.reason.clone().map(|x| (r.index, x));
                    }
                }
            }
            Event::Discarded { index, .. } => {
                self.kept = self.kept.saturating_sub(1);
                if self.decide.as_ref().is_some_and(|(i, _)| i == index) {
                    self.decide = None;
                }
            }
            Event::Failed { index, .. } => {
                self.failed += 1;
                let opened = self.recording.is_some_and(|(i, _)| i == *index);
                self.after_episode();
                if !opened && !self.plan.attended && self.timed() {
                    // Its file could not even be opened: the next would fail alike.
                    let why = format!("episode {index} could not be written");
                    self.done = Some(why.clone());
                    self.stopped = Some(why);
                }
            }
            Event::Refused { reason, force, .. } => {
                if !force && !self.plan.attended {
                    self.done = Some(reason.clone());
                    self.stopped = Some(reason.clone());
                }
                self.waiting = Some(reason.clone());
                self.retry_at = Some(Instant::now() + RETRY);
            }
            Event::Task(_) | Event::DiskLow(_) => {}
        }
    }

    fn steer(&mut self, recorder: &Recorder) {
        let now = Instant::now();
        if let (Some((_, since)), Some(limit)) = (self.recording, self.plan.episode_s) {
            if !self.ending && since.elapsed().as_secs_f64() >= limit {
                self.ending = true;
                recorder.send(if self.plan.attended {
                    Command::End
                } else {
                    Command::Stop(Label::Unlabeled)
                });
            }
            return;
        }
        // A held episode counts until it is discarded.
        let counted = self.kept
            + u64::from(self.held.is_some())
            + if self.plan.attended { 0 } else { self.failed };
        if self.plan.episodes.is_some_and(|n| counted >= n) {
            if self.held.is_none() && self.decide.is_none() {
                self.done = Some(format!("{} episodes kept", self.kept));
            } else if self.decide.is_none()
                && !self.keep_sent
                && self.reset_until.is_some_and(|t| now >= t)
            {
                // Nothing more to record: the held episode is kept once its reset is over (in
                // a session without a timer it waits for its label, keep, discard or quit).
                recorder.send(Command::Keep);
                self.keep_sent = true;
            }
            return;
        }
        let ready = self.recording.is_none()
            && self.decide.is_none()
            && self.timed()
            && self.reset_until.is_none_or(|t| now >= t)
            && self.retry_at.is_none_or(|t| now >= t);
        if !ready {
            return;
        }
        if self.plan.attended {
            let live = recorder.liveness();
            if !live.is_ready() {
                let why = format!("waiting for topics: {}", live.problems().join("; "));
                if self.waiting.as_ref() != Some(&why) {
                    tracing::info!("{why}");
                }
                self.waiting = Some(why);
                self.retry_at = Some(now + Duration::from_millis(250));
                return;
            }
        }
        self.retry_at = Some(now + RETRY);
        self.waiting = None;
        recorder.send(Command::Start);
    }

    /// Where the session is now.
    pub fn phase(&self) -> Phase {
        if self.done.is_some() {
            return Phase::Done;
        }
        if let Some((index, since)) = self.recording {
            let elapsed_s = since.elapsed().as_secs_f64();
            return Phase::Recording {
                index,
                elapsed_s,
                left_s: self.plan.episode_s.map(|l| (l - elapsed_s).max(0.0)),
            };
        }
        if let Some((index, reason)) = &self.decide {
            return Phase::Decide {
                index: *index,
                reason: reason.clone(),
            };
        }
        if let Some(t) = self.reset_until.filter(|t| *t > Instant::now()) {
            return Phase::Reset {
                held: self.held,
                left_s: t.saturating_duration_since(Instant::now()).as_secs_f64(),
            };
        }
        match &self.waiting {
            Some(w) => Phase::Waiting(w.clone()),
            None if self.held.is_some() => Phase::Reset {
                held: self.held,
                left_s: 0.0,
            },
            None => Phase::Idle,
        }
    }
}
