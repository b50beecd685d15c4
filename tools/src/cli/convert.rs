//! `scaledp convert` and `scaledp dataset`.

use std::path::PathBuf;

use clap::{Args, Subcommand};

use super::common::parse_action_space;

/// A codec for `convert --video`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum VideoArg {
    /// AV1 (rav1e), LeRobot's default.
    Av1,
    /// H.264 (openh264).
    H264,
}

/// What `convert --unlabeled` does with episodes recorded without a success or failure label.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum UnlabeledArg {
    /// Convert them, stored with label `unlabeled` (never as successes).
    Keep,
    /// Leave them out.
    Skip,
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
    #[arg(long, value_name = "SECONDS", default_value_t = scaledp_converter::align::DEFAULT_REORDER_WINDOW_S)]
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
    /// What to do with episodes recorded without a success or failure label (a plain stop, a
    /// timed or unattended recording, a bag from elsewhere): keep (stored with label
    /// `unlabeled` in meta/episodes/) or skip. No default: when any input is unlabelled and
    /// this is not given, convert names them and converts nothing.
    #[arg(long, value_enum, value_name = "keep|skip")]
    pub unlabeled: Option<UnlabeledArg>,
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
