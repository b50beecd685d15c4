//! One episode of the soak: start the recorder, open the load for the episode's seconds
//! (sampling the recorder's memory and watching the disk), close it, wait until the recorder
//! has received everything sent, stop, then check the file against what was sent and what
//! the recorder reported, and delete it unless kept.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Result;
use indicatif::ProgressBar;
use scaledp_recorder::FreeSpace;
use scaledp_testkit::cpu_seconds;
use serde_json::Value;

use super::child::{vm_rss, Worker};
use super::figures::{EpisodeFigures, RssSample, TopicCount};
use super::publish::LoadPublisher;

/// How long the recorder may take to receive what was sent once the load stops.
const DRAIN_TIMEOUT: Duration = Duration::from_secs(30);
/// How long finishing an episode's file may take.
const FINISH_TIMEOUT: Duration = Duration::from_secs(300);

/// What an episode needs from the soak.
pub struct Ctx<'a> {
    /// The recorder.
    pub worker: &'a mut Worker,
    /// The load.
    pub publisher: &'a LoadPublisher,
    /// The output directory (its disk is watched).
    pub out: &'a Path,
    /// Keep the file.
    pub keep: bool,
    /// End the episode when the disk has less free (bytes).
    pub min_free: u64,
    /// Seconds between memory samples.
    pub sample_every: Duration,
    /// When the soak's first episode started (samples are timed from it).
    pub t0: Instant,
    /// The memory samples.
    pub rss: &'a mut Vec<RssSample>,
    /// When the last sample was taken.
    pub last_sample: Option<Instant>,
    /// Progress.
    pub bar: &'a ProgressBar,
}

impl Ctx<'_> {
    /// Takes a memory sample when one is due.
    fn sample(&mut self, force: bool) {
        let due = self
            .last_sample
            .is_none_or(|t| t.elapsed() >= self.sample_every);
        if !(due || force) {
            return;
        }
        if let Some(rss) = vm_rss(self.worker.pid()) {
            self.rss.push((self.t0.elapsed().as_secs_f64(), rss));
        }
        self.last_sample = Some(Instant::now());
    }
}

/// Free bytes on `dir`'s disk (None when it cannot be told).
pub fn free_bytes(dir: &Path) -> Option<u64> {
    FreeSpace::system().query(dir).ok()
}

/// Per topic: received so far, from the worker's status.
pub fn received(status: &Value) -> BTreeMap<String, u64> {
    status["topics"]
        .as_object()
        .map(|m| {
            m.iter()
                .map(|(t, v)| (t.clone(), v[0].as_u64().unwrap_or(0)))
                .collect()
        })
        .unwrap_or_default()
}

/// Waits until the recorder has received, of every topic, what it had before the load was
/// opened (`before`) and the `sent` messages since; whether it did, and how long that took.
/// (Counted from `before`, not from zero: what was sent before a subscription reached the
/// publisher never arrives, and must not hold every later episode up.)
pub fn drain(
    worker: &Worker,
    topics: &[String],
    before: &BTreeMap<String, u64>,
    sent: &[u64],
    timeout: Duration,
) -> (bool, f64) {
    let start = Instant::now();
    loop {
        let got = worker.status().map(|s| received(&s)).unwrap_or_default();
        let all = topics.iter().zip(sent).all(|(t, &n)| {
            got.get(t).copied().unwrap_or(0) >= before.get(t).copied().unwrap_or(0) + n
        });
        if all || start.elapsed() > timeout {
            return (all, start.elapsed().as_secs_f64());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The check of a finished file: its summary's counts against the recorder's report.
fn check(path: &Path, reported: &Value) -> String {
    let summary = match scaledp_converter::mcap_summary(path) {
        Ok(s) => s,
        Err(e) => return e.one_line(),
    };
    if !summary
        .metadata
        .iter()
        .any(|m| m == scaledp_schema::episode::END_RECORD)
    {
        return format!(
            "{}: no {} metadata record",
            path.display(),
            scaledp_schema::episode::END_RECORD
        );
    }
    let empty = serde_json::Map::new();
    for (topic, n) in reported.as_object().unwrap_or(&empty) {
        let in_file = summary.messages.get(topic).copied().unwrap_or(0);
        if Some(in_file) != n.as_u64() {
            return format!(
                "{}: {topic}: {in_file} messages in the file, the recorder reported {n}",
                path.display()
            );
        }
    }
    "ok".into()
}

/// Runs one episode of `seconds` of load.
pub fn run(ctx: &mut Ctx<'_>, number: usize, seconds: f64) -> Result<EpisodeFigures> {
    let pid = ctx.worker.pid();
    let (cpu0, wall0) = (cpu_seconds(pid), Instant::now());
    let first_sample = ctx.rss.len();
    ctx.worker.send("start")?;
    let started = ctx.worker.wait_event("started", Duration::from_secs(30))?;
    let topics = ctx.publisher.topics().to_vec();
    let before = ctx.publisher.counts();
    let received_before = ctx
        .worker
        .status()
        .map(|s| received(&s))
        .unwrap_or_default();
    ctx.publisher.open();
    let opened = Instant::now();
    let mut cut = None;
    let mut last_disk = Instant::now();
    while opened.elapsed().as_secs_f64() < seconds {
        let left = seconds - opened.elapsed().as_secs_f64();
        std::thread::sleep(Duration::from_secs_f64(left.clamp(0.0, 0.25)));
        ctx.sample(false);
        if last_disk.elapsed() >= Duration::from_secs(1) {
            last_disk = Instant::now();
            if let Some(free) = free_bytes(ctx.out).filter(|&f| f < ctx.min_free) {
                cut = Some(format!(
                    "{:.1} GB free on the output disk, below --min-free-gb",
                    free as f64 / 1e9
                ));
                break;
            }
        }
        ctx.bar.set_position(ctx.t0.elapsed().as_secs());
    }
    ctx.publisher.close(Duration::from_secs(10))?;
    let load_s = opened.elapsed().as_secs_f64();
    let after = ctx.publisher.counts();
    let sent: Vec<u64> = after.iter().zip(&before).map(|(a, b)| a.0 - b.0).collect();
    let (drained, drain_s) = drain(ctx.worker, &topics, &received_before, &sent, DRAIN_TIMEOUT);
    ctx.worker.send("stop")?;
    let fin = ctx.worker.wait_event("finished", FINISH_TIMEOUT)?;
    let cpu_s = cpu0.zip(cpu_seconds(pid)).map(|(a, b)| b - a);
    // The recorder's own disk guard may have ended it first.
    let cut = cut.or_else(|| {
        fin["cut"]
            .as_str()
            .map(|why| format!("the recorder: {why}"))
    });
    ctx.sample(true);
    let samples = &ctx.rss[first_sample..];
    let rss_max = samples.iter().map(|s| s.1).max();
    let rss_end = samples.last().map(|s| s.1);
    let mut per_topic = BTreeMap::new();
    for (i, t) in topics.iter().enumerate() {
        let (s0, b0, m0) = before[i];
        let (s1, b1, m1) = after[i];
        per_topic.insert(
            t.clone(),
            TopicCount {
                offered: (s1 - s0) + (m1 - m0),
                sent: s1 - s0,
                recorded: fin["messages"][t].as_u64().unwrap_or(0),
                dropped: fin["dropped"][t].as_u64().unwrap_or(0),
                sent_bytes: b1 - b0,
                recorded_bytes: fin["bytes"][t].as_u64().unwrap_or(0),
            },
        );
    }
    let path = PathBuf::from(fin["path"].as_str().unwrap_or_default());
    let file_bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
    let check = check(&path, &fin["messages"]);
    let deleted = !ctx.keep && std::fs::remove_file(&path).is_ok();
    tracing::info!(
        "episode {number}: {load_s:.1} s of load, {:.0} MB, check {check}{}",
        file_bytes as f64 / 1e6,
        if deleted { ", deleted" } else { "" }
    );
    Ok(EpisodeFigures {
        index: started["index"].as_u64().unwrap_or(number as u64),
        load_s,
        recorder_s: fin["duration_s"].as_f64().unwrap_or(0.0),
        drain_s,
        drained,
        topics: per_topic,
        file_bytes,
        check,
        cut,
        cpu_s,
        wall_s: wall0.elapsed().as_secs_f64(),
        deleted,
        rss_max,
        rss_end,
    })
}
