//! What `scaledp record --view` is recording, live ([`RecordView`]): the recorder's Zenoh
//! callbacks hand messages to a worker thread through a small queue and skip frames rather than
//! wait, so the view never slows the recorder. [`Own`] is the one-recording sink the live views
//! (this one and those of [`crate::runs`]) share.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, SyncSender, TrySendError};
use std::thread::JoinHandle;

use rerun::{RecordingStream, Scalars, TextLog};
use scaledp_converter::Serialization;
use scaledp_schema::rig::{Rig, TopicSpec};

use crate::error::{Error, Result};
use crate::layout;
use crate::recording::Collector;
use crate::sink::{Sink, Target};

/// Messages waiting for the live worker; more are skipped.
const QUEUE: usize = 32;

pub(crate) fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// A recording stream on its own sink, finished with it (dropped unfinished: a partial file is
/// removed).
pub(crate) struct Own {
    rec: Option<RecordingStream>,
    sink: Option<Sink>,
}

impl Own {
    pub fn open(target: &Target, id: &str, name: &str) -> Result<Self> {
        let sink = Sink::open(target)?;
        let rec = sink.stream(id, name)?;
        rec.set_log_tick_enabled(false);
        rec.set_log_time_enabled(false);
        Ok(Self {
            rec: Some(rec),
            sink: Some(sink),
        })
    }
    pub fn rec(&self) -> Result<&RecordingStream> {
        self.rec
            .as_ref()
            .ok_or_else(|| Error::Rerun("the view is finished".into()))
    }
    pub fn finish(mut self) -> Result<Option<PathBuf>> {
        match (self.sink.take(), self.rec.take()) {
            (Some(sink), Some(rec)) => sink.finish(vec![rec]),
            _ => Err(Error::Rerun("the view is finished".into())),
        }
    }
}

impl Drop for Own {
    fn drop(&mut self) {
        if let Some(sink) = self.sink.take() {
            sink.abandon(self.rec.take().into_iter().collect());
        }
    }
}

/// How much of a live recording is shown. Defaults: images at most 320 px wide and 5 per
/// second per camera, joint states at most 50 per second per topic.
#[derive(Debug, Clone, Copy)]
pub struct LiveOptions {
    max_width: u32,
    image_hz: f64,
    joint_hz: f64,
}

impl Default for LiveOptions {
    fn default() -> Self {
        Self {
            max_width: 320,
            image_hz: 5.0,
            joint_hz: 50.0,
        }
    }
}

impl LiveOptions {
    /// Images wider than this are downsampled.
    pub fn max_width(mut self, px: u32) -> Self {
        self.max_width = px.max(16);
        self
    }
    /// Most images shown per second per camera.
    pub fn image_hz(mut self, hz: f64) -> Self {
        self.image_hz = hz.max(0.1);
        self
    }
    /// Most joint states shown per second per topic.
    pub fn joint_hz(mut self, hz: f64) -> Self {
        self.joint_hz = hz.max(0.1);
        self
    }
}

/// The recorder's figures for one topic, as `scaledp_recorder::TopicStatus` has them.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TopicFigures {
    /// ROS 2 topic.
    pub topic: String,
    /// Messages received so far.
    pub received: u64,
    /// Payload bytes received so far.
    pub bytes: u64,
    /// Messages the recorder's queue dropped so far.
    pub dropped: u64,
    /// Messages lost upstream so far.
    pub upstream_gaps: u64,
}

enum Job {
    Message {
        topic: usize,
        log_ns: u64,
        payload: Vec<u8>,
    },
    Status {
        at_ns: u64,
        topics: Vec<TopicFigures>,
        queued_bytes: usize,
    },
    Text(String),
}

/// What `scaledp record --view` streams: the rig's topics as they arrive (images downsampled,
/// rates limited), the recorder's rates, drops and queue, and episode events.
///
/// ```no_run
/// # fn main() -> scaledp_viewer::Result<()> {
/// use scaledp_viewer::{LiveOptions, RecordView, Target};
/// let rig = scaledp_schema::Rig::builtin("franka_2zed").expect("shipped rig");
/// let view = RecordView::start(&Target::Spawn, &rig, LiveOptions::default())?;
/// // From the recorder's Zenoh callback for topic `i` of `rig.topics()`:
/// view.message(0, &[/* CDR payload */]);
/// view.finish()?;
/// # Ok(()) }
/// ```
pub struct RecordView {
    topics: Vec<TopicSpec>,
    tx: Option<SyncSender<Job>>,
    last_ns: Vec<AtomicU64>,
    min_gap_ns: Vec<u64>,
    skipped: AtomicU64,
    worker: Option<JoinHandle<Result<()>>>,
    own: Option<Own>,
}

impl RecordView {
    /// Opens a live recording named after the rig at `target`.
    pub fn start(target: &Target, rig: &Rig, opts: LiveOptions) -> Result<Self> {
        let own = Own::open(
            target,
            &format!("live-{}", now_ns()),
            &format!("live: {}", rig.name),
        )?;
        let topics = rig.topics();
        let min_gap_ns = topics
            .iter()
            .map(|t| {
                (1e9 / if t.is_image {
                    opts.image_hz
                } else {
                    opts.joint_hz
                }) as u64
            })
            .collect();
        let (tx, rx) = sync_channel::<Job>(QUEUE);
        let rec = own.rec()?.clone();
        let rig = rig.clone();
        let specs = topics.clone();
        let worker = std::thread::Builder::new()
            .name("scaledp-live-view".into())
            .spawn(move || -> Result<()> {
                let mut collector = Collector::live(&rec, Some(opts.max_width), Some(rig));
                let mut last: Option<(u64, Vec<TopicFigures>)> = None;
                for job in rx {
                    match job {
                        Job::Message {
                            topic,
                            log_ns,
                            payload,
                        } => {
                            let t = &specs[topic];
                            collector.message(
                                &t.topic,
                                &t.message_type,
                                log_ns,
                                Serialization::Cdr,
                                &payload,
                            )?;
                        }
                        Job::Status {
                            at_ns,
                            topics,
                            queued_bytes,
                        } => {
                            log_status(&rec, at_ns, &topics, queued_bytes, last.as_ref())?;
                            last = Some((at_ns, topics));
                        }
                        Job::Text(s) => {
                            rec.reset_time();
                            rec.set_timestamp_nanos_since_epoch(
                                layout::RECEIVE_TIME,
                                now_ns() as i64,
                            );
                            rec.log(layout::LOG, &TextLog::new(s))
                                .map_err(Error::rerun)?;
                        }
                    }
                }
                Ok(())
            })
            .map_err(|e| Error::Rerun(format!("live view thread: {e}")))?;
        Ok(Self {
            last_ns: topics.iter().map(|_| AtomicU64::new(0)).collect(),
            topics,
            tx: Some(tx),
            min_gap_ns,
            skipped: AtomicU64::new(0),
            worker: Some(worker),
            own: Some(own),
        })
    }

    /// The topics in the order [`Self::message`] numbers them (the rig's `topics()`).
    pub fn topics(&self) -> &[TopicSpec] {
        &self.topics
    }

    /// A message of topic `topic` (its CDR payload) as it arrives. Cheap and non-blocking: a
    /// message within the rate limit of the last one shown, or one that finds the queue full,
    /// is skipped (and counted).
    pub fn message(&self, topic: usize, payload: &[u8]) {
        let (Some(last), Some(&gap)) = (self.last_ns.get(topic), self.min_gap_ns.get(topic)) else {
            return;
        };
        let now = now_ns();
        let prev = last.load(Ordering::Relaxed);
        if now.saturating_sub(prev) < gap
            || last
                .compare_exchange(prev, now, Ordering::Relaxed, Ordering::Relaxed)
                .is_err()
        {
            return;
        }
        self.send(Job::Message {
            topic,
            log_ns: now,
            payload: payload.to_vec(),
        });
    }

    fn send(&self, job: Job) {
        if let Some(tx) = &self.tx {
            if let Err(TrySendError::Full(_)) = tx.try_send(job) {
                self.skipped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// The recorder's figures now: plotted as rates (Hz, MB/s), drops and gaps per topic, and
    /// the queue's fill (MB).
    pub fn status(&self, topics: Vec<TopicFigures>, queued_bytes: usize) {
        self.send(Job::Status {
            at_ns: now_ns(),
            topics,
            queued_bytes,
        });
    }

    /// A line in the text log (episode started, finished, failed…).
    pub fn event(&self, text: impl Into<String>) {
        self.send(Job::Text(text.into()));
    }

    /// Messages skipped because the live queue was full.
    pub fn skipped(&self) -> u64 {
        self.skipped.load(Ordering::Relaxed)
    }

    /// Stops the worker and flushes the stream.
    pub fn finish(mut self) -> Result<()> {
        self.tx.take();
        if let Some(w) = self.worker.take() {
            w.join()
                .map_err(|_| Error::Rerun("live view thread panicked".into()))??;
        }
        self.own.take().map(Own::finish).transpose().map(drop)
    }
}

impl Drop for RecordView {
    fn drop(&mut self) {
        self.tx.take();
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
    }
}

fn log_status(
    rec: &RecordingStream,
    at_ns: u64,
    topics: &[TopicFigures],
    queued_bytes: usize,
    last: Option<&(u64, Vec<TopicFigures>)>,
) -> Result<()> {
    let r = Error::rerun;
    rec.reset_time();
    rec.set_timestamp_nanos_since_epoch(layout::RECEIVE_TIME, at_ns as i64);
    rec.log(
        "recorder/queue_mb",
        &Scalars::new([queued_bytes as f64 / 1e6]),
    )
    .map_err(r)?;
    let Some((t0, before)) = last else {
        return Ok(());
    };
    let dt = at_ns.saturating_sub(*t0) as f64 * 1e-9;
    if dt <= 0.0 {
        return Ok(());
    }
    let mut mb = 0.0;
    for t in topics {
        let Some(b) = before.iter().find(|b| b.topic == t.topic) else {
            continue;
        };
        let part = layout::topic(&t.topic).replacen("topics/", "", 1);
        let rate = t.received.saturating_sub(b.received) as f64 / dt;
        mb += t.bytes.saturating_sub(b.bytes) as f64 / dt / 1e6;
        rec.log(format!("recorder/rate_hz/{part}"), &Scalars::new([rate]))
            .map_err(r)?;
        rec.log(
            format!("recorder/lost/{part}"),
            &Scalars::new([(t.dropped + t.upstream_gaps) as f64]),
        )
        .map_err(r)?;
    }
    rec.log("recorder/mb_per_s", &Scalars::new([mb])).map_err(r)
}
