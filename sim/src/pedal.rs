//! Driving a `scaledp record` process the way a foot pedal does: words on its control key
//! (`<prefix>/control`), and its JSON events on `<prefix>/status` read back, so a simulated
//! operator's episodes start and end where the recorder's files do.

use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde::Serialize;
use zenoh::Wait;

use crate::{Error, Result};

/// A pedal on a recorder's control key.
pub struct Pedal {
    control: zenoh::pubsub::Publisher<'static>,
    events: mpsc::Receiver<serde_json::Value>,
    _status: zenoh::pubsub::Subscriber<()>,
}

impl Pedal {
    /// Declares the control publisher and the status subscriber under `prefix` (e.g.
    /// `scaledp/recorder`).
    pub fn new(session: &zenoh::Session, prefix: &str) -> Result<Self> {
        let prefix = prefix.trim_matches('/');
        let zerr = |key: String| {
            move |e: zenoh::Error| Error::Zenoh {
                key: key.clone(),
                reason: e.to_string(),
            }
        };
        let control_key = format!("{prefix}/control");
        let control = session
            .declare_publisher(control_key.clone())
            .wait()
            .map_err(zerr(control_key))?;
        let (tx, events) = mpsc::channel();
        let status_key = format!("{prefix}/status");
        let status = session
            .declare_subscriber(status_key.clone())
            .callback(move |s| {
                if let Ok(v) = serde_json::from_slice(&s.payload().to_bytes()) {
                    let _ = tx.send(v);
                }
            })
            .wait()
            .map_err(zerr(status_key))?;
        Ok(Self {
            control,
            events,
            _status: status,
        })
    }

    /// Waits up to `timeout` for a recorder to listen on the control key.
    pub fn wait_for_recorder(&self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        loop {
            if self
                .control
                .matching_status()
                .wait()
                .is_ok_and(|m| m.matching())
            {
                return true;
            }
            if Instant::now() >= deadline {
                return false;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Sends `word` (`start`, `success`, `failure`, …) and waits up to `timeout` for one of the
    /// recorder's `events` (e.g. `started`, or `finished` / `failed`): the event, if it came.
    pub fn press(
        &self,
        word: &str,
        events: &[&str],
        timeout: Duration,
    ) -> Option<serde_json::Value> {
        while self.events.try_recv().is_ok() {}
        if let Err(e) = self.control.put(word.to_string()).wait() {
            tracing::warn!("control key: {e}");
        }
        let deadline = Instant::now() + timeout;
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            match self.events.recv_timeout(left) {
                Ok(v) if events.iter().any(|e| v["event"] == *e) => return Some(v),
                Ok(_) => {}
                Err(_) => return None,
            }
        }
        None
    }
}

/// One line of a collection's log (`collect.jsonl`): which file holds which seed's episode and
/// how it went.
#[derive(Debug, Clone, Serialize)]
pub struct EpisodeLine<'a> {
    /// The episode file, if one was written.
    pub episode: Option<&'a str>,
    /// The rig's name.
    pub rig: &'a str,
    /// The episode's seed.
    pub seed: u64,
    /// `success` or `failure`, as the task's scorer said.
    pub outcome: &'a str,
    /// Seconds from the operator's start to its end.
    pub duration_s: f64,
    /// When the task became a success (s after the reset).
    pub time_to_success_s: Option<f64>,
}

impl EpisodeLine<'_> {
    /// The line as compact JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}
