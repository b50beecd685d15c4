//! Terminal plumbing: logging to stderr, the live status line, short topic labels.

use std::time::Instant;

use scaledp_recorder::{Phase, Status};
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
        let head = match now.episode {
            Some((i, start)) => format!("● REC #{i} {}", clock(start.elapsed().as_secs_f64())),
            None => "○ idle".to_string(),
        };
        self.line(head, now)
    }

    /// The line of a session the pilot steers: its phase (with the countdown of a timed
    /// session), the task, the disk when it runs low, then the figures.
    pub fn render_phase(&mut self, now: Status, phase: &Phase) -> String {
        let mut head = match phase {
            Phase::Recording {
                index,
                elapsed_s,
                left_s,
            } => match left_s {
                Some(left) => format!(
                    "● REC #{index} {} │ {} left",
                    clock(*elapsed_s),
                    clock(*left)
                ),
                None => format!("● REC #{index} {}", clock(*elapsed_s)),
            },
            Phase::Reset { held, left_s } => {
                let next = if *left_s > 0.0 {
                    format!("◌ RESET {} → next", clock(*left_s))
                } else {
                    "◌ between episodes".to_string()
                };
                match held {
                    Some(i) => format!("{next} │ #{i} ended: [y]/[n] label [d] discard [r] redo"),
                    None => next,
                }
            }
            Phase::Decide { index, .. } => {
                format!("⚠ #{index} convert would reject it: [k] keep [r] re-record")
            }
            Phase::Waiting(why) => format!("⏸ {}", shorten(why, 90)),
            Phase::Idle => "○ idle".to_string(),
            Phase::Done => "■ done".to_string(),
        };
        head.push_str(&format!(" │ task: {}", shorten(&now.task, 40)));
        if let Some(d) = now.disk.as_ref().filter(|d| d.low) {
            head.push_str(&format!(
                " │ DISK {:.1} min left",
                d.minutes_left.unwrap_or(0.0)
            ));
        }
        self.line(head, now)
    }

    fn line(&mut self, head: String, now: Status) -> String {
        let t = Instant::now();
        let mut parts = vec![head];
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

/// `mm:ss.s`.
fn clock(s: f64) -> String {
    format!("{:02}:{:04.1}", (s / 60.0) as u64, s % 60.0)
}

/// `text` cut to `n` characters, with an ellipsis when cut.
fn shorten(text: &str, n: usize) -> String {
    if text.chars().count() <= n {
        return text.to_string();
    }
    let mut out: String = text.chars().take(n.saturating_sub(1)).collect();
    out.push('…');
    out
}
