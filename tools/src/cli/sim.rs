//! `scaledp sim`, `scaledp collect` and `scaledp demo`: the simulated rig's flags.

use std::path::PathBuf;

use clap::Args;

use super::common::{CameraCodecArg, CompressionArg, KeysArg, NetArgs, OperatorArg};

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
    /// Times an episode `scaledp convert` would reject is recorded again (a loaded machine can
    /// stall the simulated rig); the rejected file moves to `discarded/`.
    #[arg(long, default_value_t = 2)]
    pub retries: u64,
}
