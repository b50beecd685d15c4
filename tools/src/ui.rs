//! Terminal plumbing: logging to stderr, the live status line, short topic labels.

use std::time::Instant;

use scaledp_recorder::Status;
use scaledp_schema::Rig;

/// Logs go to stderr; `-v` / `-vv` raise the level, `-q` lowers it, `RUST_LOG` overrides both.
pub fn init_logging(verbose: u8, quiet: bool) {
    let level = match (quiet, verbose) {
        (true, _) => "warn",
        (false, 0) => "info,zenoh=warn,zenoh_transport=warn,zenoh_link_tcp=warn",
        (false, 1) => "debug,zenoh=info",
        _ => "trace",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .try_init();
}

/// `scaledp … | head`: when the reader of stdout has gone, the command ends quietly with
/// status 0 (as ripgrep does) instead of panicking in `println!`. Only stdout is concerned: the
/// Rust runtime ignores SIGPIPE, so a closed socket or a dead simulator's pipe stays an error
/// the command reports (restoring SIGPIPE's default would kill the process there instead).
pub fn quiet_on_closed_stdout() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let p = info.payload();
        let msg = p
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| p.downcast_ref::<&str>().copied())
            .unwrap_or("");
        if msg.starts_with("failed printing to stdout") && msg.contains("Broken pipe") {
            std::process::exit(0);
        }
        default(info)
    }));
}

/// Short labels for a rig's topics, in `Rig::topics` order: camera names, arm names, `<arm>_grip`.
pub fn topic_labels(rig: &Rig) -> Vec<String> {
    let mut out: Vec<String> = rig.cameras.iter().map(|c| c.name.clone()).collect();
    for a in &rig.arms {
        out.push(a.name.clone());
        if a.gripper.is_some() {
            out.push(format!("{}_grip", a.name));
        }
    }
    out
}

/// Turns successive status snapshots into a one-line summary with rates.
pub struct StatusLine {
    labels: Vec<String>,
    last: Option<(Instant, Status)>,
}

impl StatusLine {
    /// A status line for topics labelled `labels`.
    pub fn new(labels: Vec<String>) -> Self {
        Self { labels, last: None }
    }

    /// The line for `now` (rates since the previous call).
    pub fn render(&mut self, now: Status) -> String {
        let t = Instant::now();
        let mut parts = Vec::new();
        parts.push(match now.episode {
            Some((i, start)) => {
                let s = start.elapsed().as_secs_f64();
                format!("● REC #{i} {:02}:{:04.1}", (s / 60.0) as u64, s % 60.0)
            }
            None => "○ idle".to_string(),
        });
        let (mut mbps, mut dropped) = (0.0, 0);
        for (i, topic) in now.topics.iter().enumerate() {
            dropped += topic.dropped + topic.upstream_gaps;
            let hz = match &self.last {
                Some((lt, last)) if t > *lt => {
                    let dt = (t - *lt).as_secs_f64();
                    let prev = &last.topics[i];
                    mbps += (topic.bytes - prev.bytes) as f64 / dt / 1e6;
                    (topic.received - prev.received) as f64 / dt
                }
                _ => 0.0,
            };
            let label = self
                .labels
                .get(i)
                .map_or(topic.topic.as_str(), String::as_str);
            parts.push(format!("{label} {hz:.0}Hz"));
        }
        parts.push(format!("{mbps:.1} MB/s"));
        parts.push(format!("drops {dropped}"));
        parts.push(format!("queue {} MB", now.queued_bytes >> 20));
        self.last = Some((t, now));
        parts.join(" │ ")
    }
}
