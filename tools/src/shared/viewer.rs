//! The rerun viewer as the commands use it: showing files, the live tap of `record --view`, the
//! training curves of `train --view` (each a clear error in a build without the `view` feature).

use anyhow::Result;

/// Shows `paths` (recordings, bags or datasets) in a new rerun viewer, or the one at `url`.
#[cfg(feature = "view")]
pub fn show(paths: &[String], url: Option<&str>) -> Result<()> {
    use scaledp_viewer::{Target, ViewOptions};
    let target = url.map_or(Target::Spawn, |u| Target::Connect(u.to_string()));
    let summary = scaledp_viewer::view(paths, ViewOptions::new(), &target)?;
    eprintln!("sent {} rollouts to the rerun viewer", summary.shown.len());
    Ok(())
}

/// `--view` without rerun: a clear error.
#[cfg(not(feature = "view"))]
pub fn show(_: &[String], _: Option<&str>) -> Result<()> {
    anyhow::bail!("--view: this scaledp was built without the `view` feature (rerun)")
}

/// `record --view`: a tap on the recorder's Zenoh session feeding a live rerun recording.
#[cfg(feature = "view")]
pub mod live {
    use std::sync::{Arc, Mutex, OnceLock};
    use std::time::{Duration, Instant};

    use anyhow::Result;
    use scaledp_recorder::keys::{bridge_key, rmw_key_expr};
    use scaledp_recorder::{Event, Recorder};
    use scaledp_schema::Rig;
    use scaledp_viewer::{LiveOptions, RecordView, Target, TopicFigures};
    use zenoh::sample::Sample;
    use zenoh::Wait;

    struct Tap {
        view: Arc<RecordView>,
        subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
        last_status: Instant,
    }

    static TAP: OnceLock<Mutex<Option<Tap>>> = OnceLock::new();

    /// Starts the live view: `url` None spawns a viewer, else streams to it.
    pub fn start(recorder: &Recorder, rig: &Rig, namespace: &str, url: Option<&str>) -> Result<()> {
        let target = url.map_or(Target::Spawn, |u| Target::Connect(u.to_string()));
        let view = Arc::new(RecordView::start(&target, rig, LiveOptions::default())?);
        let mut subscribers = Vec::new();
        for (i, t) in view.topics().iter().enumerate() {
            for key in [
                bridge_key(namespace, &t.topic),
                rmw_key_expr(&t.topic, &t.message_type),
            ] {
                let v = view.clone();
                let sub = recorder
                    .session()
                    .declare_subscriber(key)
                    .callback(move |s: Sample| v.message(i, &s.payload().to_bytes()))
                    .wait()
                    .map_err(|e| anyhow::anyhow!("live view subscriber: {e}"))?;
                subscribers.push(sub);
            }
        }
        let tap = Tap {
            view,
            subscribers,
            last_status: Instant::now(),
        };
        *TAP.get_or_init(|| Mutex::new(None))
            .lock()
            .map_err(|_| anyhow::anyhow!("live view lock"))? = Some(tap);
        Ok(())
    }

    /// The recorder's figures (at most 4 times a second) and an episode event, if any.
    pub fn update(recorder: &Recorder, event: Option<&Event>) {
        let Some(Ok(mut guard)) = TAP.get().map(Mutex::lock) else {
            return;
        };
        let Some(tap) = guard.as_mut() else { return };
        if let Some(e) = event {
            tap.view.event(match e {
                Event::Started { index, path } => {
                    format!("episode {index} started: {}", path.display())
                }
                Event::Finished(r) => format!(
                    "episode {} finished: {}, {:.1} s",
                    r.index, r.outcome, r.duration_s
                ),
                Event::Failed { index, error } => format!("episode {index} failed: {error}"),
                Event::Ended { index, verdict } => {
                    format!("episode {index} ended: {}", verdict.line())
                }
                Event::Discarded { index, .. } => format!("episode {index} discarded"),
                Event::Refused { reason, .. } => reason.clone(),
                Event::Task(task) => format!("task: {task}"),
                Event::DiskLow(line) => line.clone(),
            });
        }
        if tap.last_status.elapsed() >= Duration::from_millis(250) {
            tap.last_status = Instant::now();
            let s = recorder.status();
            let topics = s
                .topics
                .iter()
                .map(|t| TopicFigures {
                    topic: t.topic.clone(),
                    received: t.received,
                    bytes: t.bytes,
                    dropped: t.dropped,
                    upstream_gaps: t.upstream_gaps,
                })
                .collect();
            tap.view.status(topics, s.queued_bytes);
        }
    }

    /// Stops the tap (before the recorder closes its session) and flushes the view.
    pub fn finish() -> Result<()> {
        let Some(tap) = TAP.get().and_then(|m| m.lock().ok()?.take()) else {
            return Ok(());
        };
        for s in tap.subscribers {
            let _ = s.undeclare().wait();
        }
        if let Ok(view) = Arc::try_unwrap(tap.view) {
            view.finish()?;
        }
        Ok(())
    }
}

/// Without the `view` feature `record --view` is refused.
#[cfg(not(feature = "view"))]
pub mod live {
    use anyhow::Result;
    use scaledp_recorder::{Event, Recorder};
    use scaledp_schema::Rig;

    /// Refuses: built without rerun.
    pub fn start(_: &Recorder, _: &Rig, _: &str, _: Option<&str>) -> Result<()> {
        anyhow::bail!("--view: this scaledp was built without the `view` feature (rerun)")
    }
    /// Nothing to update.
    pub fn update(_: &Recorder, _: Option<&Event>) {}
    /// Nothing to finish.
    pub fn finish() -> Result<()> {
        Ok(())
    }
}

/// `scaledp train --view`: the loss, learning rate and validation figures on a `step` timeline.
#[cfg(feature = "view")]
pub mod curves {
    use anyhow::Result;
    use scaledp_viewer::{Target, TrainingView};

    /// A training run's curves in a rerun viewer.
    pub struct Curves(TrainingView);

    impl Curves {
        /// A new viewer (`url` None) or the one at `url`, showing the run `name`.
        pub fn start(url: Option<&str>, name: &str) -> Result<Self> {
            let target = url.map_or(Target::Spawn, |u| Target::Connect(u.to_string()));
            Ok(Curves(TrainingView::start(&target, name)?))
        }
        /// One optimizer step.
        pub fn step(&self, step: u64, loss: f64, lr: f64) -> Result<()> {
            Ok(self.0.log_step(step, loss, lr)?)
        }
        /// One validation figure.
        pub fn validation(&self, step: u64, name: &str, value: f64) -> Result<()> {
            Ok(self.0.log_validation(step, name, value)?)
        }
        /// Flushes the stream.
        pub fn finish(self) -> Result<()> {
            self.0.finish()?;
            Ok(())
        }
    }
}

/// `scaledp train --view` without rerun: a clear error.
#[cfg(not(feature = "view"))]
pub mod curves {
    use anyhow::Result;

    /// Never made: this build has no viewer.
    pub struct Curves;

    impl Curves {
        /// Fails: no `view` feature.
        pub fn start(_: Option<&str>, _: &str) -> Result<Self> {
            anyhow::bail!("--view: this scaledp was built without the `view` feature (rerun)")
        }
        /// Unreachable without a viewer.
        pub fn step(&self, _: u64, _: f64, _: f64) -> Result<()> {
            Ok(())
        }
        /// Unreachable without a viewer.
        pub fn validation(&self, _: u64, _: &str, _: f64) -> Result<()> {
            Ok(())
        }
        /// Unreachable without a viewer.
        pub fn finish(self) -> Result<()> {
            Ok(())
        }
    }
}
