//! Every flag of `scaledp`, in one place.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

/// How a command ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExitStatus {
    /// 0: everything worked.
    Success,
    /// 1: the command failed.
    Error,
    /// 3: the command finished, but some data was lost (drops, failed episodes).
    DataLost,
}

impl From<scaledp_bench::Outcome> for ExitStatus {
    fn from(o: scaledp_bench::Outcome) -> Self {
        match o {
            scaledp_bench::Outcome::Completed => ExitStatus::Success,
            scaledp_bench::Outcome::DataLost => ExitStatus::DataLost,
        }
    }
}

impl From<ExitStatus> for std::process::ExitCode {
    fn from(s: ExitStatus) -> Self {
        Self::from(match s {
            ExitStatus::Success => 0,
            ExitStatus::Error => 1,
            ExitStatus::DataLost => 3,
        })
    }
}

/// scaledp: record teleoperated demonstrations and turn them into training data for ScaleDP.
#[derive(Debug, Parser)]
#[command(name = "scaledp", version, about, long_about = None)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
    /// More log output (-v debug, -vv trace); RUST_LOG overrides.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    /// Only warnings and errors on stderr.
    #[arg(short, long, global = true)]
    pub quiet: bool,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a simulated rig that publishes cameras and joint states over Zenoh like a real one
    /// and follows commands (a Cartesian TCP target and a gripper opening per arm).
    Sim(SimArgs),
    /// Collect demonstrations in one process: the simulated task, its scripted teleoperator and
    /// the recorder, one episode per seed, each labelled by the task's scorer.
    Collect(CollectArgs),
    /// Record teleop episodes from Zenoh into one MCAP file each.
    Record(RecordArgs),
    /// Repair an MCAP file cut short by a crash, keeping every complete chunk.
    Recover(RecoverArgs),
    /// Convert recordings and ROS bags into a LeRobot v3.0 dataset.
    Convert(ConvertArgs),
    /// Work with converted datasets.
    #[command(subcommand)]
    Dataset(DatasetCommand),
    /// Measure throughput and cost.
    #[command(subcommand)]
    Bench(scaledp_bench::BenchCommand),
    /// Train a ScaleDP policy on a LeRobot dataset (checkpoints, metrics.jsonl, --resume).
    Train(Box<crate::commands::train::TrainArgs>),
    /// Run a checkpoint over a recorded episode: predicted vs recorded actions and their error.
    Predict(crate::commands::predict::PredictArgs),
    /// Drive a rig with a checkpoint over Zenoh: observations built as the converter built the
    /// training data, clamped Cartesian commands at the control rate (--dry-run prints them).
    Serve(crate::commands::serve::ServeArgs),
    /// A checkpoint's success rate on seeded, held-out episodes of the simulated task (95 %
    /// Wilson interval, per-episode outcomes, a JSON report).
    Eval(crate::commands::eval::EvalArgs),
    /// The paper's comparisons at this machine's scale (non-causal vs causal attention, Ti vs S)
    /// with one recipe, chosen on validation seeds, reported on test seeds with controls.
    #[command(subcommand)]
    Experiment(scaledp_experiment::ExperimentCommand),
    /// The whole path on a simulated rig: records a few short episodes over loopback, converts
    /// them into a LeRobot dataset and runs one epoch of the training-data loader.
    Demo(DemoArgs),
    /// Show recordings, bags and LeRobot datasets in the rerun viewer (or write an .rrd file).
    View(ViewArgs),
}

/// Where the Zenoh session connects and listens.
#[derive(Debug, Clone, Args)]
pub struct NetArgs {
    /// A standard Zenoh config file (json5): mode, endpoints, TLS, scouting…
    #[arg(long, value_name = "FILE")]
    pub zenoh_config: Option<PathBuf>,
    /// Endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable; overrides the file).
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// Endpoint to listen on (repeatable; overrides the file).
    #[arg(long, value_name = "ENDPOINT")]
    pub listen: Vec<String>,
}

/// The codec of simulated cameras (`sim --camera-codec`, `collect --camera-codec`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CameraCodecArg {
    /// Each camera as `foxglove_msgs/msg/CompressedVideo`: H.264 Annex B, no B-frames, an IDR
    /// with SPS/PPS once a second.
    H264,
}

impl CameraCodecArg {
    /// Makes every camera of `rig` publish (and be recorded) as this codec.
    pub fn apply(self, rig: &mut scaledp_schema::Rig) {
        for c in &mut rig.cameras {
            c.encoding = Some("h264".into());
            c.compressed = false;
        }
    }
}

/// Key layout of the simulated publishers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum KeysArg {
    /// zenoh-bridge-ros2dds: the topic without its leading '/'.
    Bridge,
    /// rmw_zenoh: <domain>/<topic>/<type>/<hash>, with attachments.
    Rmw,
}

/// Who drives the simulated arms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OperatorArg {
    /// Nobody in-process: the arms hold still until commands arrive over Zenoh.
    None,
    /// The scripted expert, as a teleoperator publishing leader commands.
    Scripted,
}

/// `scaledp sim`.
#[derive(Debug, Args)]
pub struct SimArgs {
    /// Rig file, or the name of a shipped rig (franka_2zed, bimanual_ur5_3rs, or their
    /// simulated task cells with command topics, franka_sim, bimanual_ur5_sim).
    #[arg(long, default_value = "franka_2zed")]
    pub rig: String,
    /// Publish the cameras as compressed video (default: the rig's own, raw images unless it
    /// says otherwise).
    #[arg(long, value_enum, value_name = "CODEC")]
    pub camera_codec: Option<CameraCodecArg>,
    /// Seed of the first episode (cubes, targets, the operator's hands) and of the jitter and
    /// latencies; episode i uses seed + i.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Stop after this many seconds (default: until Ctrl-C).
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
    /// Key layout.
    #[arg(long, value_enum, default_value = "bridge")]
    pub keys: KeysArg,
    /// Bridge namespace prefix for the keys.
    #[arg(long, default_value = "")]
    pub namespace: String,
    /// Drive the arms with the scripted teleoperator. Alone it demonstrates episode after
    /// episode; with --episodes it runs that many and drives a recorder's control key around
    /// each (start, then success or failure as the task's scorer says).
    #[arg(long, value_enum, default_value = "none")]
    pub operator: OperatorArg,
    /// With --operator scripted: this many episodes (seeds seed, seed + 1, …), then exit.
    #[arg(long)]
    pub episodes: Option<u64>,
    /// With --operator scripted: score the operator over --episodes seeds (default 100) in
    /// simulated time, without cameras or network, and print its success rate.
    #[arg(long)]
    pub score: bool,
    /// Longest episode (s): an operator not done by then fails it.
    #[arg(long, default_value_t = 30.0)]
    pub max_seconds: f64,
    /// Prefix of the recorder's control and status keys the episodes drive.
    #[arg(long, default_value = "scaledp/recorder")]
    pub control_prefix: String,
    /// Seconds to wait for a recorder on the control key before the first episode.
    #[arg(long, default_value_t = 30.0)]
    pub wait_recorder: f64,
    /// Prefix of the simulator's own keys (<prefix>/reset in, <prefix>/task out).
    #[arg(long, default_value = "scaledp/sim")]
    pub sim_prefix: String,
    /// Network settings; by default the sim listens on tcp/127.0.0.1:7447 like the bridge.
    #[command(flatten)]
    pub net: NetArgs,
}

/// `scaledp collect`.
#[derive(Debug, Args)]
pub struct CollectArgs {
    /// Rig file, or the name of a shipped rig (franka_sim and bimanual_ur5_sim carry command
    /// topics, so the commands are recorded too; metaworld/<task> runs one of MetaWorld's 50
    /// tasks with its scripted expert).
    #[arg(long, default_value = "franka_sim")]
    pub rig: String,
    /// Publish and record the cameras as compressed video (default: as the rig says).
    #[arg(long, value_enum, value_name = "CODEC")]
    pub camera_codec: Option<CameraCodecArg>,
    /// Episodes to collect.
    #[arg(long, default_value_t = 100)]
    pub episodes: u64,
    /// Collect until this many episodes succeeded instead (at most 2N + 10 seeds): N
    /// demonstrations when the expert sometimes fails (failures are recorded and labelled, and
    /// `convert` skips them).
    #[arg(long, value_name = "N", conflicts_with = "episodes")]
    pub successes: Option<u64>,
    /// Directory for episode_NNNNNN.mcap files (numbering continues after existing ones) and
    /// collect.jsonl (seed and outcome of each episode).
    #[arg(long)]
    pub out: PathBuf,
    /// Seed of the first episode; episode i uses seed + i.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The task instruction stored with each episode (default: the cube task in words).
    #[arg(long)]
    pub task: Option<String>,
    /// Longest episode (s): an operator not done by then fails it.
    #[arg(long, default_value_t = 30.0)]
    pub max_seconds: f64,
    /// Chunk compression.
    #[arg(long, value_enum, default_value = "lz4")]
    pub compression: CompressionArg,
    /// Network settings of the in-process session (by default it only listens on a free
    /// loopback port, so nothing else sees it; --listen lets a viewer or serve look in).
    #[command(flatten)]
    pub net: NetArgs,
}

/// Chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CompressionArg {
    /// No compression.
    None,
    /// LZ4 (fast).
    Lz4,
    /// Zstandard level 1 (smaller).
    Zstd,
}

/// `scaledp record`.
#[derive(Debug, Args)]
pub struct RecordArgs {
    /// Rig file, or the name of a shipped rig.
    #[arg(long)]
    pub rig: String,
    /// Directory for episode_NNNNNN.mcap files (numbering continues after existing ones).
    #[arg(long)]
    pub out: PathBuf,
    /// The task instruction stored with each episode.
    #[arg(long)]
    pub task: String,
    /// Who teleoperates (default: $USER).
    #[arg(long)]
    pub operator: Option<String>,
    /// Record this many episodes, then exit.
    #[arg(long)]
    pub episodes: Option<u64>,
    /// Stop each episode after this many seconds (unattended runs).
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
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
    /// Never read the keyboard, even on a terminal (control over Zenoh only).
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

/// A codec for `convert --video`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum VideoArg {
    /// AV1 (rav1e), LeRobot's default.
    Av1,
    /// H.264 (openh264).
    H264,
}

/// `scaledp convert`.
#[derive(Debug, Args)]
pub struct ConvertArgs {
    /// MCAP files, ROS 1 .bag files, rosbag2 directories or .db3 files, or directories holding
    /// them (searched recursively; *.partial files and discarded/ directories are skipped);
    /// s3://bucket/prefix/ lists a prefix the same way.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// The dataset directory or s3://bucket/prefix (created, or extended: inputs already in it
    /// are skipped).
    #[arg(long)]
    pub out: PathBuf,
    /// Rig file or shipped rig name mapping topics to cameras and arms (default: the rig stored
    /// in each recording, else detected from message types and joint names).
    #[arg(long)]
    pub rig: Option<String>,
    /// Read camera or arm NAME (or <arm>_gripper, <arm>_command) from TOPIC instead (repeatable).
    #[arg(long = "topic", value_name = "NAME=TOPIC", value_parser = parse_pair)]
    pub topics: Vec<(String, String)>,
    /// Target frame rate (default: the rig's control rate).
    #[arg(long)]
    pub fps: Option<f64>,
    /// Output image size, WIDTHxHEIGHT.
    #[arg(long, default_value = "320x240", value_parser = parse_size)]
    pub size: (u32, u32),
    /// JPEG quality of the stored images.
    #[arg(long, default_value_t = 90, value_parser = clap::value_parser!(u8).range(1..=100))]
    pub jpeg_quality: u8,
    /// Store the cameras as LeRobot video features (MP4 under videos/, LeRobot's settings:
    /// yuv420p, a keyframe every 2 frames, CRF 30) instead of JPEG images in the Parquet files.
    #[arg(long, value_enum, value_name = "CODEC")]
    pub video: Option<VideoArg>,
    /// The space of observation.state and action: tcp (6D TCP pose by forward kinematics and
    /// gripper opening per arm) or joints (joint positions and gripper opening per arm, a leader
    /// arm's JointState commands as the action: ALOHA's and LeRobot's convention).
    #[arg(long = "action", default_value = "tcp", value_parser = parse_action_space)]
    pub action_space: scaledp_schema::ActionSpace,
    /// Leave out the depth of cameras the rig gives a depth topic (observation.depth.<camera>).
    #[arg(long)]
    pub no_depth: bool,
    /// Task instruction for inputs that store none (bags).
    #[arg(long)]
    pub task: Option<String>,
    /// A camera frame older than this many frame periods invalidates a tick.
    #[arg(long, default_value_t = 1.5)]
    pub stale_periods: f64,
    /// Reject an episode when more than this fraction of its ticks are invalid.
    #[arg(long, default_value_t = 0.05)]
    pub max_invalid: f64,
    /// Align on log (receive) times instead of header stamps.
    #[arg(long)]
    pub log_time: bool,
    /// Put a message back in stamp order when it is stamped up to this long before one stored
    /// earlier on its topic (a wobbling driver, a second publisher); further back is a clock jump
    /// and the episode is rejected.
    #[arg(long, value_name = "SECONDS", default_value_t = 0.1)]
    pub reorder_window: f64,
    /// Convert only slice I of N of the sorted inputs (e.g. $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT).
    #[arg(long, value_name = "I/N", value_parser = parse_shard)]
    pub shard: Option<(usize, usize)>,
    /// Episodes converted at once (default: the number of cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Rebuild the dataset from scratch instead of skipping inputs already converted.
    #[arg(long)]
    pub overwrite: bool,
    /// Target size of each data file (MiB; LeRobot's `data_files_size_in_mb`, which LeRobot
    /// measures in MiB too).
    #[arg(long, alias = "file-size-mb", default_value_t = 100)]
    pub file_size_mib: u64,
    /// Convert episodes recorded with outcome `failure` too.
    #[arg(long)]
    pub include_failures: bool,
    /// Split an input into episodes wherever nothing was logged for this many seconds (long
    /// bags holding many demonstrations).
    #[arg(long, value_name = "SECONDS")]
    pub split_gap: Option<f64>,
    /// Where bags and rosbag2 directories from object storage are downloaded, and where the
    /// working copy of a dataset written to object storage lives (default: the system's
    /// temporary directory).
    #[arg(long, value_name = "DIR")]
    pub work_dir: Option<PathBuf>,
}

fn parse_pair(s: &str) -> Result<(String, String), String> {
    let (k, v) = s
        .split_once('=')
        .ok_or("expected NAME=TOPIC, e.g. wrist=/cam/wrist/image_raw")?;
    Ok((k.to_string(), v.to_string()))
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once('x')
        .ok_or("expected WIDTHxHEIGHT, e.g. 320x240")?;
    let p = |v: &str| {
        v.parse::<u32>()
            .ok()
            .filter(|&x| x > 0)
            .ok_or(format!("bad size '{s}'"))
    };
    Ok((p(w)?, p(h)?))
}

fn parse_shard(s: &str) -> Result<(usize, usize), String> {
    let (i, n) = s.split_once('/').ok_or("expected I/N, e.g. 0/4")?;
    let (i, n): (usize, usize) = (
        i.parse().map_err(|_| "bad I")?,
        n.parse().map_err(|_| "bad N")?,
    );
    if n == 0 || i >= n {
        return Err(format!("shard {i}/{n}: need 0 <= I < N"));
    }
    Ok((i, n))
}

/// `scaledp dataset`.
#[derive(Debug, Subcommand)]
pub enum DatasetCommand {
    /// Join datasets (e.g. the shards of one batch), re-indexing episodes and re-aggregating stats.
    Merge(MergeArgs),
}

/// `scaledp dataset merge`.
#[derive(Debug, Args)]
pub struct MergeArgs {
    /// Datasets (directories or s3://bucket/prefix), in order.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// The merged dataset, a directory or s3://bucket/prefix (replaced if it exists).
    #[arg(long)]
    pub out: PathBuf,
    /// Target size of each data file (MiB).
    #[arg(long, alias = "file-size-mb", default_value_t = 100)]
    pub file_size_mib: u64,
    /// Skip inputs that hold nothing at all (a shard that had no inputs) instead of failing.
    #[arg(long)]
    pub skip_empty: bool,
    /// Where data files of datasets in object storage are downloaded, and where the working
    /// copy of a merged dataset written to object storage lives.
    #[arg(long, value_name = "DIR")]
    pub work_dir: Option<PathBuf>,
}

/// `scaledp demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Rig file, or the name of a shipped rig.
    #[arg(long, default_value = "franka_2zed")]
    pub rig: String,
    /// Output directory.
    #[arg(long, default_value = "scaledp-demo")]
    pub out: PathBuf,
    /// Episodes to record.
    #[arg(long, default_value_t = 3)]
    pub episodes: u64,
    /// Seconds per episode.
    #[arg(long, default_value_t = 4.0)]
    pub duration: f64,
    /// Seed of the simulated rig.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Samples per batch of the loader epoch at the end.
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u64).range(1..))]
    pub batch_size: u64,
    /// Steps of the short ScaleDP-Ti training run at the end (0: stop after the loader).
    #[arg(long, default_value_t = 30)]
    pub train_steps: u64,
}

/// `scaledp view`.
#[derive(Debug, Args)]
pub struct ViewArgs {
    /// Recordings (.mcap, also a .partial one), ROS 1 .bag files, rosbag2 directories or .db3
    /// files, directories of them, or LeRobot v3.0 datasets (a directory or s3://bucket/prefix).
    #[arg(required = true, value_name = "PATH")]
    pub paths: Vec<String>,
    /// Only this episode: a dataset's episode_index, or the N-th input of a directory
    /// (repeatable; default: every episode).
    #[arg(long, value_name = "N")]
    pub episode: Vec<u64>,
    /// Write an .rrd file instead of showing a viewer.
    #[arg(long, value_name = "OUT.rrd", conflicts_with = "connect")]
    pub save: Option<PathBuf>,
    /// Stream to a rerun viewer already running, e.g. rerun+http://host:9876/proxy.
    #[arg(long, value_name = "URL")]
    pub connect: Option<String>,
    /// Downsample images wider than this (pixels).
    #[arg(long, value_name = "PX")]
    pub max_width: Option<u32>,
    /// Rig file or shipped rig name mapping topics (default: the rig stored in the input, else
    /// detected).
    #[arg(long)]
    pub rig: Option<String>,
    /// Actions drawn ahead of each frame as the action chunk.
    #[arg(long, default_value_t = 16)]
    pub chunk: usize,
    /// Show recordings' state and action in this space (tcp or joints), as `scaledp convert
    /// --action` would convert them; a dataset is shown in its own.
    #[arg(long = "action", default_value = "tcp", value_parser = parse_action_space)]
    pub action_space: scaledp_schema::ActionSpace,
    /// A policy checkpoint whose predicted chunks are drawn beside the dataset's (one dataset,
    /// with --episode).
    #[arg(long, value_name = "DIR")]
    pub checkpoint: Option<PathBuf>,
}

fn parse_action_space(s: &str) -> Result<scaledp_schema::ActionSpace, String> {
    s.parse()
}
