//! `scaledp record` and `scaledp recover`.

use std::path::PathBuf;

use clap::Args;

use super::common::{CompressionArg, NetArgs};

/// `scaledp record`.
#[derive(Debug, Args)]
pub struct RecordArgs {
    /// Rig file, or the name of a shipped rig.
    #[arg(long)]
    pub rig: String,
    /// Directory for episode_NNNNNN.mcap files (numbering continues after existing ones).
    #[arg(long)]
    pub out: PathBuf,
    /// The task instruction stored with each episode. Given several times, the first is
    /// recorded first and `t` (or the control word `next-task`) moves on to the next; given
    /// once, `t` asks for a new one between episodes (`task <text>` on the control key sets any).
    #[arg(long, required = true, value_name = "TEXT")]
    pub task: Vec<String>,
    /// Who teleoperates (default: $USER).
    #[arg(long)]
    pub operator: Option<String>,
    /// Record this many episodes, then exit (discarded and re-recorded ones do not count).
    #[arg(long)]
    pub episodes: Option<u64>,
    /// A timed, attended session: each episode ends after this many seconds (earlier with a
    /// key or control word), held for a label during the reset.
    #[arg(long, value_name = "SECONDS", conflicts_with = "duration", value_parser = positive_seconds)]
    pub episode_time: Option<f64>,
    /// With --episode-time: seconds between an episode's end and the next start (a countdown
    /// in the status line; [space] starts at once).
    #[arg(
        long,
        value_name = "SECONDS",
        default_value_t = 10.0,
        requires = "episode_time",
        value_parser = seconds
    )]
    pub reset_time: f64,
    /// An unattended run: each episode ends after this many seconds, unlabelled, and the next
    /// starts at once; no keyboard, no prompts.
    #[arg(long, value_name = "SECONDS", value_parser = positive_seconds)]
    pub duration: Option<f64>,
    /// Warn (status line and status key) when the output disk holds less than this many
    /// minutes of recording.
    #[arg(long, value_name = "MINUTES", default_value_t = 5.0)]
    pub disk_warn_minutes: f64,
    /// Start episodes whatever the free space on the output disk, and let a full disk fail the
    /// episode being written (the disk guard refuses an episode that cannot fit and ends one
    /// before the disk is full).
    #[arg(long)]
    pub no_disk_guard: bool,
    /// Chunk compression.
    #[arg(long, value_enum, default_value = "lz4")]
    pub compression: CompressionArg,
    /// Target chunk size (MiB).
    #[arg(long, default_value_t = 8)]
    pub chunk_mib: u64,
    /// Payload bytes the writer queue may hold before dropping (MiB).
    #[arg(long, default_value_t = 1024)]
    pub queue_mib: usize,
    /// Prefix of the control (<prefix>/control) and status (<prefix>/status) keys.
    #[arg(long, default_value = "scaledp/recorder")]
    pub control_prefix: String,
    /// Namespace zenoh-bridge-ros2dds runs with, if any.
    #[arg(long, default_value = "")]
    pub namespace: String,
    /// Seconds to wait for every topic to be live before an unattended run starts.
    #[arg(long, default_value_t = 10.0)]
    pub wait_topics: f64,
    /// Never read the keyboard, even on a terminal (control over Zenoh only; starts are then
    /// not held back by missing topics, which each episode lists instead).
    #[arg(long)]
    pub no_keyboard: bool,
    /// Stream what is recorded (downsampled images, joints, rates and drops) to a rerun viewer:
    /// a new one, or the one at URL (e.g. rerun+http://host:9876/proxy).
    #[arg(long, value_name = "URL", num_args = 0..=1)]
    pub view: Option<Option<String>>,
    /// Also record topic NAME of type TYPE (pkg/msg/Name), verbatim. NAME may be a glob ('*'
    /// one level, '**' any number, e.g. /robot/**): each matching topic gets a channel from
    /// its first message. Without TYPE the type comes from the rmw_zenoh key or the bridge's
    /// announcement (repeatable).
    #[arg(long = "topic", value_name = "NAME[:TYPE]", value_parser = parse_topic_pattern)]
    pub topics: Vec<scaledp_recorder::TopicPattern>,
    /// Look up the definitions of types scaledp does not know as <DIR>/share/<pkg>/msg/<Name>.msg
    /// or <DIR>/<pkg>/msg/<Name>.msg, after the prefixes of AMENT_PREFIX_PATH (repeatable).
    #[arg(long, value_name = "DIR")]
    pub msg_path: Vec<PathBuf>,
    /// Record a rig topic under another name, as ROS remaps one: FROM:=TO, e.g.
    /// /tf:=/robot1/tf (repeatable).
    #[arg(long, value_name = "FROM:=TO", value_parser = parse_remap)]
    pub remap: Vec<(String, String)>,
    /// Network settings; by default a peer connecting to tcp/127.0.0.1:7447.
    #[command(flatten)]
    pub net: NetArgs,
}

/// A duration in seconds, 0 or more.
fn seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(x) if x.is_finite() && x >= 0.0 => Ok(x),
        _ => Err(format!("'{s}' is not a number of seconds (0 or more)")),
    }
}

/// A duration in seconds, more than 0.
fn positive_seconds(s: &str) -> Result<f64, String> {
    match seconds(s) {
        Ok(x) if x > 0.0 => Ok(x),
        _ => Err(format!("'{s}' is not a number of seconds above 0")),
    }
}

fn parse_topic_pattern(s: &str) -> Result<scaledp_recorder::TopicPattern, String> {
    s.parse()
}

/// `FROM:=TO`, ROS's remapping syntax.
fn parse_remap(s: &str) -> Result<(String, String), String> {
    let (from, to) = s
        .split_once(":=")
        .ok_or("expected FROM:=TO, e.g. /tf:=/robot1/tf")?;
    let name = |n: &str| {
        let ok = !n.is_empty()
            && !n.ends_with('/')
            && n.trim_start_matches('/')
                .split('/')
                .all(|w| !w.is_empty() && w.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'));
        if ok {
            Ok(n.to_string())
        } else {
            Err(format!(
                "'{n}' is not a ROS 2 topic name (letters, digits, '_', '/')"
            ))
        }
    };
    Ok((name(from)?, name(to)?))
}

/// `scaledp recover`.
#[derive(Debug, Args)]
pub struct RecoverArgs {
    /// The damaged file (e.g. episode_000003.mcap.partial), or an object (s3://bucket/key).
    pub input: PathBuf,
    /// Output (default: the name without .partial, or <stem>.recovered.mcap), a path or URL.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Where an object is downloaded and recovered before the result is uploaded (default: the
    /// system's temporary directory).
    #[arg(long, value_name = "DIR")]
    pub work_dir: Option<PathBuf>,
}
